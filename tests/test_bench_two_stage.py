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


def _args(**changes):
    """bench_two_stage's parsed options (its own parser), with ``changes`` on the command line.
    Its --out is a temporary folder, removed after (main makes it before its first stage;
    "unused" in the working directory was left in the checkout by every test run)."""
    import tempfile

    scratch = tempfile.TemporaryDirectory(prefix="flexcal-bench-two-stage-")
    argv = ["--out", str(Path(scratch.name) / "unused"), "--seed", "3", "--scenario", "table1",
            "--keep-standard", "41"]
    for key, value in changes.items():
        argv += [f"--{key}"] if value is True else [f"--{key}", str(value)]
    captured = {}

    def stop(args):  # the parsed options, then out before any stage runs
        captured["args"] = args
        raise _Parsed

    from unittest import mock

    with scratch, mock.patch.object(bench_two_stage, "stage_plan", lambda out, args: stop(args)), \
            pytest.raises(_Parsed):
        bench_two_stage.main(argv)
    return captured["args"]


class _Parsed(Exception):
    pass


def _heldout_verify_argv(argv: list[str]) -> list[str]:
    """The flexcal verify argv that bench_design_heldout.main builds from ``argv`` (flexcal's
    main replaced by one that records it and fails, so nothing runs)."""
    from unittest import mock

    seen = []
    with mock.patch("flexcal.validation.cli.main", lambda a: seen.append(a) or 1), pytest.raises(SystemExit):
        bench_design_heldout.main(argv)
    return seen[0]


def test_designed_verify_starts_at_stage_one_and_every_stage_gets_the_dimension_terms(tmp_path):
    """Issue #28 (session 19): the designed verify starts its fits at stage 1's report.json
    (flexcal verify --start), by default; --dimension-terms reaches every verify and design, and
    the argv each stage builds is one flexcal's own parsers accept with those values."""
    from flexcal.validation.cli import build_parser

    args = _args(**{"dimension-terms": "quadratic"})
    assert args.start and args.dimension_terms == "quadratic"
    plan = bench_two_stage.stage_plan(tmp_path, args)
    assert list(plan) == ["standard", "design:designed-k41", "designed-k41"]
    stage1_report = tmp_path / "std-quadratic" / "report.json"
    assert plan["standard"]["start"] is None  # stage 1 starts at the prior mean: there is nothing before it
    assert plan["designed-k41"]["start"] == stage1_report
    assert plan["designed-k41"]["trajectory"] == tmp_path / "design-k41-quadratic" / "trajectory.csv"
    assert plan["design:designed-k41"]["at"] == stage1_report

    verify_parser = build_parser("verify")
    for name in ("standard", "designed-k41"):
        stage = plan[name]
        bench = bench_two_stage.verify_argv(stage["folder"], args, stage["trajectory"], stage["start"])
        verify = verify_parser.parse_args(_heldout_verify_argv(bench))
        assert verify.dimension_terms == "quadratic" and verify.model == "consistent"
        assert verify.model_stiffness == "fem"  # what --dimension-terms quadratic needs (opening.calibration_model)
        assert (verify.start or None) == (None if stage["start"] is None else str(stage1_report))  # default ""
        assert verify.trajectory == (None if stage["trajectory"] is None else str(stage["trajectory"]))
        assert verify.seed == 3 and verify.scenario == "table1"
    design_stage = plan["design:designed-k41"]
    design = build_parser("design").parse_args(
        bench_two_stage.design_argv(design_stage["folder"], args, design_stage["at"], design_stage["extra"]))
    assert design.dimension_terms == "quadratic" and design.model == "consistent"
    assert design.at == str(stage1_report) and design.keep_standard == 41


def test_start_and_terms_name_their_own_folders(tmp_path):
    """--no-start and the linear terms keep the folder names of the runs made before these
    options (stage 1 "std", "designed-k41" started at the prior mean); a started or quadratic run
    never reuses them, and --no-start passes no --start."""
    old = bench_two_stage.stage_plan(tmp_path, _args(**{"no-start": True}))
    assert old["standard"]["folder"] == tmp_path / "std"
    assert old["designed-k41"]["folder"] == tmp_path / "designed-k41"
    assert old["designed-k41"]["start"] is None
    assert "--start" not in bench_two_stage.verify_argv(tmp_path, _args(**{"no-start": True}),
                                                        old["designed-k41"]["trajectory"], None)
    started = bench_two_stage.stage_plan(tmp_path, _args())
    assert started["standard"]["folder"] == tmp_path / "std"  # stage 1 is shared: it has no start
    assert started["designed-k41"]["folder"] == tmp_path / "designed-k41-start"
    quadratic = bench_two_stage.stage_plan(tmp_path, _args(**{"dimension-terms": "quadratic", "no-start": True}))
    folders = [plan[name]["folder"] for plan in (old, started, quadratic) for name in plan]
    assert len(set(folders)) == len(folders) - 2  # only the linear runs' stage 1 and design are shared
    assert bench_two_stage.summary_path(tmp_path, _args(**{"dimension-terms": "quadratic"})).name == \
        "two_stage-k41-quadratic-start.json"


def test_criterion_reaches_the_design_and_names_its_stages(tmp_path):
    """--criterion drives goes to flexcal design (its parser accepts it) and names the designed
    stages, so a drives run never reuses a D run's design; D (the default) keeps the old folders."""
    from flexcal.validation.cli import build_parser

    args = _args(criterion="drives", **{"dimension-terms": "quadratic"})
    plan = bench_two_stage.stage_plan(tmp_path, args)
    assert list(plan) == ["standard", "design:designed-k41-drives", "designed-k41-drives"]
    assert plan["design:designed-k41-drives"]["folder"] == tmp_path / "design-k41-drives-quadratic"
    assert plan["designed-k41-drives"]["folder"] == tmp_path / "designed-k41-drives-quadratic-start"
    assert plan["designed-k41-drives"]["trajectory"] == tmp_path / "design-k41-drives-quadratic" / "trajectory.csv"
    stage = plan["design:designed-k41-drives"]
    design = build_parser("design").parse_args(bench_two_stage.design_argv(stage["folder"], args, stage["at"],
                                                                           stage["extra"]))
    assert design.criterion == "drives" and design.keep_standard == 41
    assert bench_two_stage.summary_path(tmp_path, args).name == "two_stage-k41-drives-quadratic-start.json"
    default = bench_two_stage.stage_plan(tmp_path, _args(**{"dimension-terms": "quadratic"}))
    assert default["design:designed-k41"]["folder"] == tmp_path / "design-k41-quadratic"
    stage = default["design:designed-k41"]
    assert build_parser("design").parse_args(bench_two_stage.design_argv(stage["folder"], args, stage["at"],
                                                                         stage["extra"])).criterion == "D"


def test_pooling_per_mount_over_the_seeds():
    """benchmarks/pool_two_stage.py: per mount, the largest error and the held-out RMS as RMS over
    the seeds, the sources alone summed, z pooled n-weighted; "beats" needs all three criteria
    per mount, so a design that wins two seeds narrowly and loses one badly does not beat."""
    import math

    import pool_two_stage

    def summary(seed, worst, held, alone, z_base=(1.0, 1.0)):
        stage = {"z_rms_pure": 1.0, "n_pure": 4, "z_rms_base": z_base[0], "n_base": 6}
        return {"scenario": "table1", "seed": seed,
                "runs": {"standard": dict(stage), "designed-x": {**stage, "z_rms_base": z_base[1]}},
                "designed-x_vs_standard": {"worst_over_paper": list(worst), "heldout_rms_urad": list(held),
                                           "n_alone": list(alone)}}
    # (designed, standard) per seed, as bench_two_stage._beats writes them
    wins = [summary(1, (0.1, 0.5), (0.1, 0.2), (4, 4), z_base=(1.0, 3.0)), summary(2, (0.3, 0.1), (0.2, 0.2), (4, 4)),
            summary(3, (0.1, 0.2), (0.1, 0.3), (5, 4))]
    entry = pool_two_stage.pool(wins, "designed-x")["table1"]
    assert entry["seeds"] == [1, 2, 3] and entry["beats"]
    # sqrt((0.1^2 + 0.3^2 + 0.1^2) / 3) against sqrt((0.5^2 + 0.1^2 + 0.2^2) / 3): exact arithmetic
    assert math.isclose(entry["designed-x"]["worst_rms"], math.sqrt(0.11 / 3), rel_tol=1e-12)
    assert math.isclose(entry["standard"]["worst_rms"], math.sqrt(0.30 / 3), rel_tol=1e-12)
    assert entry["designed-x"]["alone"] == 13 and entry["standard"]["alone"] == 12
    # base z: designed 3.0 on seed 1's 6 values, 1.0 on the other 12: sqrt((6*9 + 12) / 18)
    assert math.isclose(entry["designed-x"]["z_base"][0], math.sqrt(66 / 18), rel_tol=1e-12)
    assert entry["designed-x"]["z_base"][1] == 18
    loses = wins[:2] + [summary(3, (0.9, 0.2), (0.1, 0.3), (5, 4))]  # one bad seed outweighs two good ones
    assert not pool_two_stage.pool(loses, "designed-x")["table1"]["beats"]
    fewer = wins[:2] + [summary(3, (0.1, 0.2), (0.1, 0.3), (2, 4))]  # fewer sources alone in all
    assert not pool_two_stage.pool(fewer, "designed-x")["table1"]["beats"]


@pytest.mark.slow
def test_the_designed_measurement_beats_the_standard_one_on_the_paper_mount(tmp_path):
    """Issue #28's "design >= standard": the README's two-stage path (standard trajectory, then
    `flexcal design --criterion drives --keep-standard 41 --dimension-terms quadratic` at its
    estimate, then the designed verify started there), FEM prototype, `paper` seed 1, 0.5 urad.
    The designed stage must win on all three criteria of ``_beats``: a lower largest drive error
    (over the paper's figure) among the drives both identify alone, at least as many sources
    alone, and a lower RMS predicting a held-out random walk (seed 28). Measured 2026-11-28
    (session 21, docs/calibration.md "Session 21"): 0.149 vs 0.310, 9 vs 7, 0.151 vs 0.424 urad;
    ~4 min warm (the FEM prototype's cache), more cold."""
    import json

    assert bench_two_stage.main(["--out", str(tmp_path), "--seed", "1", "--scenario", "paper", "--keep-standard", "41",
                                 "--criterion", "drives", "--dimension-terms", "quadratic"]) == 0
    summary = json.loads(next(tmp_path.glob("two_stage*.json")).read_text())
    verdict = next(v for k, v in summary.items() if k.endswith("_vs_standard"))
    assert verdict["beats"], verdict
