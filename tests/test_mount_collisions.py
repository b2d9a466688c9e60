"""The collision check of a mount (flexcal.validation.mount_solids, docs/mount.md): the
chains' CadQuery solids and the payload's box intersected pairwise; the examples pass,
crossing chains and a chain through the payload are refused in one line (exit 2)."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from flexcal.geometry.exact import exact_volume, pieces
from flexcal.geometry.mount import mount_from_table, read_mount
from flexcal.validation import cli
from flexcal.validation.mount_checks import check_mount, read_checked_mount
from flexcal.validation.mount_solids import MIN_OVERLAP, PAYLOAD, mount_solids, overlaps

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def write(tmp_path, table) -> Path:
    path = tmp_path / "m.mount.toml"
    path.write_text(tomli_w.dumps(table))
    return path


def table_of(name: str) -> dict:
    return tomllib.loads((EXAMPLES / name).read_text())


@pytest.mark.parametrize("name", ["table1.mount.toml", "paper.mount.toml", "mirror600.mount.toml"])
def test_the_example_mounts_pass(name):
    mechanism = read_mount(EXAMPLES / name)
    assert overlaps(mechanism) == []
    assert check_mount(mechanism, source=name) == []
    # the mirror places its payload box, so its chains are checked against it too
    assert (PAYLOAD in mount_solids(mechanism)) == (name == "mirror600.mount.toml")


def test_chains_whose_square_corners_overlap_are_refused(tmp_path, capsys):
    # D2 beside D1, axes 60 mm apart along the diagonal of their 50 mm sections: the inscribed
    # circles (radius 25 mm) clear each other, the squares' corners overlap by 7.6 x 7.6 mm
    table = table_of("table1.mount.toml")
    offset = 60.0 / np.sqrt(2.0)
    table["chains"][4].update(point_a_mm=[50.0, 600.0 + offset, -150.0 + offset],
                              point_b_mm=[200.0, 600.0 + offset, -150.0 + offset],
                              roll_reference=table["chains"][3]["roll_reference"])
    path = write(tmp_path, table)
    with pytest.raises(ValueError, match=r"chains D1 and D2 collide: their solids overlap by [0-9.e+]+ mm\^3") as error:
        read_checked_mount(path)
    assert str(path) in str(error.value)
    assert cli.main(["mount", str(path)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_a_chain_through_the_payload_is_refused_with_its_overlap(tmp_path, capsys):
    # the mirror's rotation drive D3 moved into the mirror's box (x 0..80, |y| <= 300, |z| <= 200 mm)
    table = table_of("mirror600.mount.toml")
    table["chains"][5].update(point_a_mm=[40.0, 120.0, -150.0], point_b_mm=[40.0, 0.0, -150.0])
    path = write(tmp_path, table)
    with pytest.raises(ValueError, match=r"chain D3 runs into the payload: their solids overlap by") as error:
        read_checked_mount(path)
    assert cli.main(["truth", "--scenario", "nominal", "--provider", "analytic", "--mount", str(path),
                     "--out", str(tmp_path / "t")]) == 2
    assert "D3 runs into the payload" in capsys.readouterr().err and not (tmp_path / "t").exists()
    # the whole chain lies inside the box: the overlap is its exact volume less its end block
    # at B (its attachment, allowed inside the payload); the booleans agree to round-off
    d3 = mount_from_table(table, source="t").chains[5].chain
    block = pieces(d3)[-1]
    expected = exact_volume(d3) - (block.x1 - block.x0) * 4 * block.half_y * block.half_z
    (hit,) = overlaps(mount_from_table(table, source="t"))
    assert (hit.first, hit.second) == ("D3", PAYLOAD)
    assert hit.volume == pytest.approx(expected, rel=1e-6)  # OpenCASCADE's fillet surfaces are exact; 1e-6 is its boolean fuzz
    assert f"{expected * 1e9:.4g} mm^3" in str(error.value)


def test_a_chain_fastened_on_the_payload_face_passes_but_one_inside_it_does_not():
    # the reference mount with its box's front face on the grating (x 0..200 mm): the load
    # chains end on the box's back face, their tilted end blocks' corners inside it (their
    # attachment: allowed); the drives D1, D2 (x 50..200 mm at y = +-600) lie inside the box
    mechanism = dataclasses.replace(read_mount(EXAMPLES / "table1.mount.toml"), payload_box_centre=(0.1, 0.0, 0.0))
    solids = mount_solids(mechanism)
    raw = solids["L1"].intersect(solids[PAYLOAD]).Volume()
    assert raw > 1e3 * MIN_OVERLAP  # the end block's corners are in the box (7500 mm^3) ...
    found = {(o.first, o.second) for o in overlaps(mechanism)}
    assert ("L1", PAYLOAD) not in found  # ... and allowed
    assert {("D1", PAYLOAD), ("D2", PAYLOAD), ("D3", PAYLOAD)} <= found


@pytest.mark.parametrize("name", ["table1.mount.toml", "mirror600.mount.toml"])
def test_the_envelopes_hold_the_solids(name):
    # the prefilter skips pairs whose envelopes are apart: each body's solid must lie inside its envelope
    from flexcal.validation.mount_solids import envelopes

    mechanism = dataclasses.replace(read_mount(EXAMPLES / name), payload_box_centre=(0.04, 0.0, 0.0))
    boxes = envelopes(mechanism)
    for body, solid in mount_solids(mechanism).items():
        box = solid.BoundingBox()
        lower, upper = np.array([box.xmin, box.ymin, box.zmin]), np.array([box.xmax, box.ymax, box.zmax])
        slack = 1e-6  # OpenCASCADE pads its bounding boxes by its tolerance (1e-7 m) and more for curved faces
        assert np.all(lower >= boxes[body][0] - slack) and np.all(upper <= boxes[body][1] + slack), body


def test_the_payload_placement_round_trips_and_is_optional():
    from flexcal.geometry.mount import mount_text

    mirror = read_mount(EXAMPLES / "mirror600.mount.toml")
    assert mirror.payload_box_centre == pytest.approx((0.04, 0.0, 0.0), abs=1e-15)  # mm -> m, round-off only
    assert mount_from_table(tomllib.loads(mount_text(mirror)), source="x") == mirror
    reference = read_mount(EXAMPLES / "table1.mount.toml")
    assert reference.payload_box_centre is None and "box_centre_mm" not in mount_text(reference)
