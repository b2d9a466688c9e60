"""The bookkeeping of benchmarks/bench_two_stage.py (the two-stage measurement of
docs/calibration.md 11): Table 1's drive rows from a verify report.json (x0 in um, CL in mm,
mu relative in %, alone = a pure base parameter) and issue #28's "beats the standard
trajectory" test. Hand-made reports, no FEM: the benchmark's figures rest on these."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
import bench_design_heldout  # noqa: E402
import bench_two_stage  # noqa: E402

DRIVES = bench_design_heldout.DRIVES


def _report(errors: dict[str, float], pure: list[str]) -> dict:
    """A verify report.json with the drives' identified value = preset + error (display units)."""
    rows = []
    for name in DRIVES:
        preset = {"x0": 0.4, "CL": 0.1, "mu": 0.9}[name.split(".")[1]]  # mm, mm, -
        error = errors.get(name, 0.0)
        rows.append({"name": name, "identified": preset + error, "preset": preset, "abs_error": abs(error),
                     "rel_error": abs(error) / preset, "z_score": error / 0.001})
    return {"parameters": rows, "base_parameters": {"pure": pure},
            "model_form_floor": {"available": True, "models": [
                {"model": "run", "name": "consistent", "all": {"rms_urad": {"theta_x": 0.1}, "max_urad": 0.2}}]}}


def test_drive_rows_in_table1_units():
    report = _report({"D3.x0": -0.0009, "D2.CL": 0.00005, "D3.mu": 0.009}, pure=["D3.x0", "D2.CL"])
    rows = bench_design_heldout.drive_rows(report)
    assert list(rows) == list(DRIVES)
    assert rows["D3.x0"]["error"] == pytest.approx(0.9)  # default rel 1e-6: 0.0009 mm -> um, float round-off only
    assert rows["D2.CL"]["error"] == pytest.approx(0.00005)  # default rel 1e-6: already mm
    assert rows["D3.mu"]["error"] == pytest.approx(1.0)  # default rel 1e-6: 0.009 of 0.9 is 1 %
    assert [n for n, r in rows.items() if r["alone"]] == ["D3.x0", "D2.CL"]
    assert bench_design_heldout.form_floor(report)["run"]["max_urad"] == 0.2
    assert bench_design_heldout.form_floor({}) == {"available": False}


def _run(errors, pure, heldout):
    report = _report(errors, pure)
    return {"drives": bench_design_heldout.drive_rows(report), "alone": pure, "heldout_rms_urad": heldout}


def test_beats_needs_all_three_criteria():
    standard = _run({"D3.x0": 0.0010, "D3.CL": 0.0001}, ["D3.x0", "D3.CL"], 0.40)
    # the largest error is taken over the sources both identify alone, each over the paper's figure:
    # D3.mu (alone only in the design) does not count, 0.9 um of 2.7 < 1.0 um of 2.7
    better = _run({"D3.x0": 0.0009, "D3.CL": 0.0001, "D3.mu": 0.05}, ["D3.x0", "D3.CL", "D3.mu"], 0.30)
    verdict = bench_two_stage._beats(better, standard)
    assert verdict["both_alone"] == ["D3.x0", "D3.CL"]
    assert verdict["beats"]
    # worse on the largest error alone: loses, though it predicts better and identifies more
    worse_error = _run({"D3.x0": 0.0011}, ["D3.x0", "D3.CL", "D3.mu"], 0.30)
    assert not bench_two_stage._beats(worse_error, standard)["beats"]
    # fewer sources alone: loses
    fewer = _run({"D3.x0": 0.0005}, ["D3.x0"], 0.30)
    assert not bench_two_stage._beats(fewer, standard)["beats"]
    # worse held-out prediction: loses
    worse_prediction = _run({"D3.x0": 0.0005}, ["D3.x0", "D3.CL"], 0.50)
    assert not bench_two_stage._beats(worse_prediction, standard)["beats"]


def test_variants_get_their_own_stages():
    """--keep-standard / --region name the designed stage's folders and summary, so that variants
    share one stage 1 and never overwrite each other's results (or the plain design's)."""
    from types import SimpleNamespace

    def name(keep, region):
        return bench_two_stage._variant(SimpleNamespace(keep_standard=keep, region=region))

    assert name(0, "workspace") == ""
    assert name(41, "workspace") == "-k41"
    assert name(41, "box") == "-k41-box"
    assert len({name(k, r) for k in (0, 33, 41) for r in ("workspace", "box", "hull")}) == 9
