"""``flexcal mount FILE --out DIR`` (docs/mount.md, "See the mount"): the picture, the STEP
and the summary are written, and the summary's figures agree with an independent
computation (the analytic model of paper Eq. 1-8, ``model.forward``, not the prototype)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from flexcal.geometry.exact import exact_volume
from flexcal.geometry.mount import read_mount
from flexcal.validation import cli
from flexcal.validation.reports.mount_view import PICTURE_SIZE

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def model_run(mechanism, inputs, clearance):
    """The paper's model at the nominal values, every drive's clearance CL = ``clearance`` [m]."""
    from flexcal.model.forward import forward
    from flexcal.model.parameters import parameter_space

    space = parameter_space(mechanism)
    values = np.array(space.nominal_full, float)
    for drive in ("D1", "D2", "D3"):
        values[list(space.all_names).index(f"{drive}.CL")] = clearance
    return forward(values[None], inputs, space=space)


@pytest.fixture(scope="module")
def mirror_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("see") / "mirror"
    status = cli.main(["mount", str(EXAMPLES / "mirror600.mount.toml"), "--out", str(out)])
    return status, out


def test_the_picture_step_and_report_are_written(mirror_run):
    from flexcal.geometry.export import import_step

    status, out = mirror_run
    assert status == 0
    png = (out / "mount.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and struct.unpack(">II", png[16:24]) == PICTURE_SIZE
    assert len(png) > 10_000  # a drawn mount, not a blank frame (a white 1400 x 1000 PNG is ~5 kB)
    mirror = read_mount(EXAMPLES / "mirror600.mount.toml")
    shape = import_step(out / "mount.step")
    assert len(shape.Solids()) == 7  # six chains and the placed payload box
    expected = sum(exact_volume(p.chain) for p in mirror.chains) + float(np.prod(mirror.payload_box))
    # STEP keeps the B-rep exactly; 1e-6 relative covers its text precision and OpenCASCADE's volume integration
    assert shape.Volume() == pytest.approx(expected, rel=1e-6)
    report = json.loads((out / "report.json").read_text())
    for placement in mirror.chains:  # |B - A| from the file's end points
        length = np.linalg.norm(np.subtract(placement.point_b, placement.point_a)) * 1e3
        assert report["chain_length_mm"][placement.name] == pytest.approx(length, abs=1e-3)  # the file's 1 um


@pytest.mark.parametrize("name", ["mirror600.mount.toml", "table1.mount.toml"])
def test_the_summary_agrees_with_the_model(name, tmp_path, mirror_run, capsys):
    from flexcal.model.trajectory import standard_trajectory

    if name == "mirror600.mount.toml":
        out = mirror_run[1]
    else:
        out = tmp_path / "t"
        assert cli.main(["mount", str(EXAMPLES / name), "--out", str(out)]) == 0
        assert "D3 at 42 points" in capsys.readouterr().out
    report = json.loads((out / "report.json").read_text())
    mechanism = read_mount(EXAMPLES / name)
    names = [p.name for p in mechanism.chains]
    at_rest = model_run(mechanism, np.zeros((1, 3)), 0.0).axial_loads[0, 0]
    loads = np.array([report["axial_load_N"][n] for n in names])
    # the model linearizes the kinematics about the design pose and models the clearance by
    # Eq. 6-7; on both example mounts it is within 0.15 % of the prototype's largest load,
    # while a wrong chain order or sign is off by the loads themselves (100 N - 3 kN)
    assert np.max(np.abs(loads - at_rest)) < 5e-3 * np.max(np.abs(at_rest))
    clearance = report["trajectory"]["clearance_mm"] * 1e-3
    assert clearance == mechanism.errors.clearance[1]
    run = model_run(mechanism, standard_trajectory(mechanism).inputs, clearance)
    in_gap = (run.clearance[0] > 0).sum(axis=0)
    counts = report["trajectory"]["points_in_clearance"]
    for i, drive in enumerate(("D1", "D2", "D3")):
        # a point where a drive's load crosses zero may fall either side in the two physics: one point
        assert abs(counts[drive] - int(in_gap[i])) <= 1, (drive, counts[drive], in_gap[i])
    classes = report["trajectory"]["class_counts"]
    for code, label in ((1, "S1"), (2, "S2"), (3, "S3")):
        assert abs(classes[label] - int(np.sum(run.point_class[0] == code))) <= 1


def test_example_and_out_together_are_refused(tmp_path, capsys):
    assert cli.main(["mount", "--example", "--out", str(tmp_path / "x")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
