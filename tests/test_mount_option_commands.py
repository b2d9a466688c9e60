"""``--mount FILE`` on the commands whose tests did not pass it: verify, identify,
sensitivity, design and inverse each read the file and show its mount in their output. All
on the analytic provider and the closed-form model, kept small (a few seconds each).

``small_mount`` is examples/table1.mount.toml with three changes, each visible in one output:
leaf L1 40 -> 31.7 mm wide (the ``nominal`` of row L1.w in verify's and identify's
report.json), x0 known to +-0.01 mm instead of +-0.5 mm (an x0 source can no longer lead
the Sobol ranking; on the reference mount D1.x0 leads with S_T ~ 1.2) and a workspace of
+-0.2/+-1/+-0.6 mrad instead of +-1/+-5/+-3 (design's postures lie inside it)."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from flexcal.geometry.mount import mount_from_table, read_mount
from flexcal.validation import cli

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
CHEAP = ["--provider", "analytic", "--model", "second-order", "--model-stiffness", "closed-form", "-q"]
L1_WIDTH_MM = 31.7  # the reference mount's leaves are 40 mm wide
WORKSPACE_MRAD = [0.2, 1.0, 0.6]  # the reference's +-1/+-5/+-3 mrad divided by 5


@pytest.fixture(scope="module")
def small_mount(tmp_path_factory) -> Path:
    table = tomllib.loads((EXAMPLES / "table1.mount.toml").read_text())
    table["name"] = "small test mount"
    table["actuators"]["initial_position_mm"] = [-0.01, 0.01]
    table["workspace"]["half_range_mrad"] = WORKSPACE_MRAD
    next(c for c in table["chains"] if c["name"] == "L1")["w_mm"] = L1_WIDTH_MM
    path = tmp_path_factory.mktemp("mount") / "small.mount.toml"
    path.write_text(tomli_w.dumps(table))
    return path


def _row(report: dict, name: str) -> dict:
    return next(r for r in report["parameters"] if r["name"] == name)


def test_verify_calibrates_on_the_mount_file(small_mount, tmp_path):
    out = tmp_path / "v"
    assert cli.main(["verify", "--scenario", "nominal", "--mount", str(small_mount), *CHEAP, "--method", "paper",
                     "--sobol-n", "8", "--particles", "40", "--iterations", "2", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    row = _row(report, "L1.w")
    assert row["nominal"] == L1_WIDTH_MM and row["preset"] == L1_WIDTH_MM  # the model's and the prototype's mount
    sidecar = json.loads((out / "curves.json").read_text())
    assert mount_from_table(sidecar["mount"], source="sidecar") == read_mount(small_mount)


def test_identify_calibrates_on_the_mount_file(small_mount, tmp_path):
    out = tmp_path / "i"
    assert cli.main(["identify", "--scenario", "nominal", "--mount", str(small_mount), *CHEAP,
                     "--particles", "40", "--iterations", "2", "--out", str(out)]) == 0
    row = _row(json.loads((out / "report.json").read_text()), "L1.w")
    assert row["nominal"] == L1_WIDTH_MM and row["preset"] == L1_WIDTH_MM


def test_sensitivity_screens_on_the_mount_file(small_mount, tmp_path):
    out = tmp_path / "s"
    assert cli.main(["sensitivity", "--scenario", "nominal", "--mount", str(small_mount), *CHEAP,
                     "--sobol-n", "16", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    # x0 spans 0.02 mm on this mount (1 mm on the reference, where D1.x0 leads with S_T 1.22)
    assert not report["summary"]["most_sensitive"].endswith(".x0"), report["ranked_overall"][:3]


def test_design_draws_its_postures_in_the_mount_files_workspace(small_mount, tmp_path):
    from flexcal.model.assembly import mechanism_matrices
    from flexcal.model.parameters import parameter_space

    out = tmp_path / "d"
    assert cli.main(["design", "--scenario", "nominal", "--mount", str(small_mount), "--model", "second-order",
                     "--model-stiffness", "closed-form",
                     "--points", "20", "--candidates", "100", "--inadequacy", "none", "-q", "--out", str(out)]) == 0
    inputs = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1, usecols=(2, 3, 4)) * 1e-3  # [m]
    space = parameter_space(read_mount(small_mount))
    gain = mechanism_matrices(space.nominal_full, space).input_gain[0, 3:, 3:]  # [rad/m], as design uses it
    angles = inputs @ gain.T
    workspace = np.array(WORKSPACE_MRAD) * 1e-3
    # candidates are drawn inside +-workspace and mapped through this gain: round-off only
    assert np.all(np.abs(angles) <= workspace * (1 + 1e-9))
    assert np.any(np.abs(angles) > 0.5 * workspace)  # and they use it (the reference's is 5x wider)


def test_inverse_solves_on_the_mount_file(tmp_path, capsys):
    from flexcal.model.inverse import inverse
    from flexcal.model.parameters import parameter_space

    mirror = EXAMPLES / "mirror600.mount.toml"
    assert cli.main(["inverse", "--target-urad", "100,-500,200", "--mount", str(mirror), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    target = np.array([[100e-6, -500e-6, 200e-6]])
    on_mirror = inverse(target, space=parameter_space(read_mount(mirror))).forward.inputs[0] * 1e3
    on_reference = inverse(target).forward.inputs[0] * 1e3
    # the same computation on the same mount: equal to round-off
    assert np.allclose(printed["inputs_mm"], on_mirror, rtol=1e-12, atol=0.0)
    assert not np.allclose(on_mirror, on_reference, rtol=1e-3)  # the mounts differ enough to tell apart
