"""The mount file (flexcal.geometry.mount, docs/mount.md): exact round trip, the reference
mount from examples/, one-line refusals, the mount checks and --mount on the commands."""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from flexcal.geometry.mount import mount_differences, mount_from_table, mount_table, mount_text, read_mount
from flexcal.geometry.params import reference_mechanism
from flexcal.validation import cli
from flexcal.validation.mount_checks import check_mount, read_checked_mount
from flexcal.validation.prototype.scenario import load_scenario

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def example_table() -> dict:
    return tomllib.loads(mount_text(reference_mechanism(), name="t"))


def write(tmp_path, table, name="m.mount.toml") -> Path:
    path = tmp_path / name
    path.write_text(tomli_w.dumps(table))
    return path


def test_reference_mount_file_is_the_reference_mechanism_exactly():
    # the built-in scenarios read examples/: equal floats, so the same curves to the byte
    assert read_mount(EXAMPLES / "table1.mount.toml") == reference_mechanism()
    paper = read_mount(EXAMPLES / "paper.mount.toml")
    assert paper == dataclasses.replace(reference_mechanism(), centre_of_gravity=(0.0, 0.0, 0.0))
    assert load_scenario("table1").space.mechanism == reference_mechanism()
    assert load_scenario("nominal").space.mechanism == reference_mechanism()
    assert load_scenario("paper").space.mechanism == paper


def test_round_trip_is_exact_for_awkward_numbers():
    rng = np.random.default_rng(5)
    reference = reference_mechanism()
    for _ in range(20):
        chains = []
        for placement in reference.chains:
            a = tuple(float(v) for v in np.asarray(placement.point_a) * rng.uniform(0.9, 1.1))
            b = tuple(float(v) for v in np.asarray(placement.point_b) + rng.normal(0, 1e-3, 3))
            length = float(np.linalg.norm(np.subtract(b, a)))
            chain = dataclasses.replace(placement.chain, length=length, width=placement.chain.width * rng.uniform(0.9, 1.1),
                                        thickness_1=placement.chain.thickness_1 * rng.uniform(0.8, 1.2))
            chains.append(dataclasses.replace(placement, chain=chain, point_a=a, point_b=b))
        mechanism = dataclasses.replace(reference, chains=tuple(chains), payload_mass=float(rng.uniform(10, 500)),
                                        centre_of_gravity=tuple(float(v) for v in rng.normal(0, 0.1, 3)),
                                        actuator_stiffness=float(rng.uniform(1e7, 1e9)),
                                        workspace=tuple(float(v) for v in rng.uniform(1e-4, 1e-2, 3)))
        once = mount_from_table(tomllib.loads(mount_text(mechanism)), source="x")
        # a float the mm grid cannot hit comes back within one ulp (the m and mm double grids differ)
        for before, after in zip(_numbers(mechanism), _numbers(once)):
            assert abs(after - before) <= np.spacing(abs(before)), (before, after)
        # and from then on exactly: a mount read from a file (a sidecar's) survives every later trip
        assert mount_from_table(tomllib.loads(mount_text(once)), source="x") == once
        assert mount_from_table(json.loads(json.dumps(mount_table(once))), source="x") == once


def _numbers(mechanism) -> list[float]:
    out = []
    for value in dataclasses.astuple(mechanism):
        out += _numbers_of(value)
    return out


def _numbers_of(value) -> list[float]:
    if isinstance(value, (tuple, list)):
        return [v for item in value for v in _numbers_of(item)]
    return [float(value)] if isinstance(value, (int, float)) else []


def test_example_command_prints_the_reference_mount(capsys):
    assert cli.main(["mount", "--example"]) == 0
    assert mount_from_table(tomllib.loads(capsys.readouterr().out), source="x") == reference_mechanism()


@pytest.mark.parametrize("change, words", [
    (lambda t: t["chains"].pop(), ["six [[chains]]", "L1, L2, L3, D1, D2"]),
    (lambda t: t["chains"][3].update(role="load"), ["chain D1", "role = 'load' must be 'drive'"]),
    (lambda t: t["chains"][1].update(a_mm=12.0), ["chain L2", "a_mm=12 mm", "<= hinge_length/2"]),
    (lambda t: t["chains"][4].update(t1_mm=0.0), ["chain D2", "t1_mm=0 mm", "> 0"]),
    (lambda t: t["chains"][5].update(point_a_mm=[200.0, 600.0, 50.0], length_mm=50.0), ["chain D3", "length_mm=50 mm"]),
    (lambda t: t["payload"].update(mass_kg=-1.0), ["payload.mass_kg = -1.0", ">= 0"]),
    (lambda t: t["material"].update(colour="red"), ["unknown key 'material.colour'"]),
])
def test_impossible_mounts_are_refused_in_one_line(tmp_path, capsys, change, words):
    table = example_table()
    change(table)
    path = write(tmp_path, table)
    with pytest.raises(ValueError) as error:
        read_mount(path)
    assert str(path) in str(error.value) and "\n" not in str(error.value)
    for word in words:
        assert word in str(error.value)
    assert cli.main(["mount", str(path)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_a_free_direction_is_named(tmp_path, capsys):
    # D3 pushing vertically through the x axis (clear of L1-L3): all six chain axes meet the x axis (D1, D2 at
    # infinity), so nothing resists theta_x
    table = example_table()
    table["chains"][5].update(point_a_mm=[300.0, 0.0, -300.0], point_b_mm=[300.0, 0.0, -150.0])
    path = write(tmp_path, table)
    with pytest.raises(ValueError, match=r"not held in rotation about x \(theta_x\)"):
        read_checked_mount(path)
    assert cli.main(["forward", "--inputs-mm", "0.1,0,0", "--mount", str(path)]) == 2
    assert "rotation about x" in capsys.readouterr().err


def test_a_workspace_beyond_the_stroke_is_refused(tmp_path, capsys):
    table = example_table()
    table["actuators"]["half_stroke_mm"] = 2.0  # the reference needs 3.6 mm (2.6 for the corners + x0 + CL)
    path = write(tmp_path, table)
    with pytest.raises(ValueError, match=r"D1 needs 3.57 mm .* more than half_stroke_mm = 2"):
        read_checked_mount(path)
    assert cli.main(["truth", "--scenario", "nominal", "--provider", "analytic", "--mount", str(path),
                     "--out", str(tmp_path / "t")]) == 2
    assert "half_stroke_mm" in capsys.readouterr().err and not (tmp_path / "t").exists()


def test_load_chains_missing_one_centre_warn_with_the_distance(tmp_path, caplog):
    table = example_table()
    table["chains"][0]["point_a_mm"][1] = 5.0  # L1's base 5 mm sideways: its axis misses O_C
    table["chains"][0].pop("length_mm")
    path = write(tmp_path, table)
    with caplog.at_level(logging.WARNING, logger="flexcal.mount"):
        read_checked_mount(path)
    assert "miss one remote centre by up to" in caplog.text
    assert check_mount(reference_mechanism()) == []  # the reference mount meets at O_C


def test_mount_option_replaces_the_data_mount_and_lists_differences(tmp_path, caplog):
    from flexcal.validation.cli.options import data_mechanism

    table = example_table()
    table["payload"]["mass_kg"] = 250.0
    table["chains"][3]["t1_mm"] = 3.5
    path = write(tmp_path, table)
    metadata = {"mount": mount_table(reference_mechanism())}
    assert data_mechanism(metadata, argparse.Namespace(mount=None)) == reference_mechanism()
    with caplog.at_level(logging.WARNING, logger="flexcal.mount"):
        mount = data_mechanism(metadata, argparse.Namespace(mount=str(path)))
    assert mount.payload_mass == 250.0 and mount.chains[3].chain.thickness_1 == 3.5e-3
    assert "payload.mass_kg: 300 -> 250" in caplog.text and "chains.D1.t1_mm: 3 -> 3.5" in caplog.text
    assert mount_differences(reference_mechanism(), reference_mechanism()) == []


def test_truth_on_a_mount_file_carries_it_in_the_sidecar(tmp_path):
    table = example_table()
    table["payload"]["mass_kg"] = 200.0
    path = write(tmp_path, table)
    out = tmp_path / "t"
    assert cli.main(["truth", "--scenario", "nominal", "--provider", "analytic", "--mount", str(path),
                     "--out", str(out), "-q"]) == 0
    metadata = json.loads((out / "curves.json").read_text())
    assert mount_from_table(metadata["mount"], source="x") == read_mount(path)


def test_chain_reference_takes_any_chain_of_the_mount(tmp_path):
    from flexcal.validation.cli.chain import build_chain

    table = example_table()
    table["chains"][1]["t2_mm"] = 5.0
    path = write(tmp_path, table)
    args = argparse.Namespace(mount=str(path), reference="L2", **{k: None for k in (
        "length_mm", "hinge_length_mm", "width_mm", "fillet_mm", "t1_mm", "t2_mm", "section_mm")})
    chain, params = build_chain(args)
    assert chain.thickness_2 == 5e-3 and params["t2"] == 5.0


def test_sweep_identification_runs_on_the_mount_of_the_file():
    from flexcal.validation.sweep.identify import mount_with_design
    from flexcal.validation.sweep.space import build_part_params, designs_from_config

    mirror = read_mount(EXAMPLES / "mirror600.mount.toml")
    table = mount_table(mirror)
    chain = {"length_mm": [120.0], "hinge_length_mm": [15.0], "width_mm": [32.0], "fillet_mm": [4.0], "t1_mm": [3.0],
             "t2_mm": [3.0], "section_mm": [40.0], "connector_mm": [8.0], "end_block_mm": [8.0]}  # fits 120 mm drives
    config = {"sweep": {"kind": "chain", "method": "grid"}, "chain": chain, "identification": {"enabled": True}}
    designs = designs_from_config(config, mount=table)
    assert designs and all(d["identification"]["mount"] == table for d in designs)
    mechanism = mount_with_design(build_part_params(designs[0]), designs[0]["identification"]["mount"])
    assert [c.point_b for c in mechanism.chains] == [c.point_b for c in mirror.chains]
    assert mechanism.payload_mass == 80.0 and {c.chain.width for c in mechanism.chains} == {0.032}  # the design's w
    with pytest.raises(ValueError, match="enable it"):
        designs_from_config({"sweep": {"kind": "chain"}}, mount=table)


def test_structure_takes_the_payload_inertia_of_the_mount():
    from flexcal.fem.mass import box_inertia
    from flexcal.validation.structure.mount import payload_mass_matrix

    at_centre = dataclasses.replace(reference_mechanism(), centre_of_gravity=(0.0, 0.0, 0.0))  # no parallel-axis part
    box = box_inertia(300.0, np.array(at_centre.payload_box))
    assert np.allclose(payload_mass_matrix(at_centre)[3:, 3:], box, rtol=1e-12)  # the file's box; round-off only
    given = dataclasses.replace(at_centre, payload_inertia=(10.0, 20.0, 30.0))
    # the given inertia passed through as is: round-off only
    assert np.allclose(payload_mass_matrix(given)[3:, 3:], np.diag([10.0, 20.0, 30.0]), rtol=1e-12)


def test_chains_that_collide_are_refused(tmp_path, capsys):
    table = example_table()
    table["chains"][4].update(point_a_mm=[50.0, 620.0, -150.0], point_b_mm=[200.0, 620.0, -150.0])  # D2 20 mm from D1
    path = write(tmp_path, table)
    with pytest.raises(ValueError, match=r"chains D1 and D2 collide: their solids overlap by [0-9.e+]+ mm\^3 around"):
        read_checked_mount(path)
    assert cli.main(["mount", str(path)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
