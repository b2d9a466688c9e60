"""The gap diagnosis end to end on blind prototype data (analytic segments, standard
trajectory x2, 0.5 urad noise), the blindness of the benchmark and the two commands."""

import json

import numpy as np
import pytest

from flexcal.validation import cli
from flexcal.validation.diagnosis.diagnose import run_diagnosis
from flexcal.validation.diagnosis.benchmark import benchmark_measurement, run_case
from flexcal.validation.measurements import Measurement, read_measurement, write_measurement
from flexcal.validation.prototype.segments import analytic_provider

REQUIRED_KEYS = {"ranking", "top_effect", "where", "noise_floor_urad"}
ROW_KEYS = {"effect", "score", "heldout_rms_before_urad", "heldout_rms_after_urad", "closure"}


@pytest.fixture(scope="module")
def provider():
    return analytic_provider()


@pytest.fixture(scope="module")
def none_case(provider):
    return benchmark_measurement("none", 0.0, 0, provider)


def test_drift_at_ten_noise_floors_is_ranked_first(provider):
    case = benchmark_measurement("drift", 10.0, 0, provider)
    report = run_diagnosis(case.measurement, rng=0).report
    assert report["top_effect"] == "drift" or "drift" in report["top_group"], report["ranking"][:3]
    assert report["ranking"][0]["effect"] == "drift"
    assert set(report["ranking"][0]) >= ROW_KEYS
    # the drift term removes most of the held-out gap above the noise floor (goal 0.7)
    assert report["ranking"][0]["closure"] >= 0.7
    # the noise floor is the sensor's 0.5 urad to within what the model's structure adds
    # (second differences / repeats can only be inflated by structure: bound 0.45..0.8)
    assert 0.45 <= report["noise_floor_urad"] <= 0.8


def test_no_effect_says_none(none_case):
    report = run_diagnosis(none_case.measurement, rng=0).report
    assert report["top_effect"] == "none", report["ranking"][:3]
    assert report["confidence"] == "none"


def test_benchmark_keeps_the_answer_from_the_diagnosis(provider, none_case):
    case = benchmark_measurement("sensor_scale", 3.0, 1, provider)
    assert case.measurement.metadata == {}  # no sidecar: the injected effect is nowhere in it
    assert case.answer["effect"] == "sensor_scale" and case.answer["injected"]
    # achieved magnitude: a scale error's signature is scale * theta, theta the angles without
    # it; here from the file's angles (table1 has no sensor offsets), whose 0.5 urad noise times
    # scale ~2e-3 moves the RMS by ~1e-3 urad at most (measured 4e-5 urad)
    scale = np.asarray(case.answer["injected"][0]["parameters"]["scale"])
    noisy_signature = case.measurement.angles * scale / (1.0 + scale)
    expected = np.sqrt(np.mean(noisy_signature**2)) * 1e6
    # the noise's share, ~1e-3 urad at most (comment above)
    assert case.answer["achieved_rms_urad"] == pytest.approx(expected, abs=1e-3)
    # as above, over the 0.5 urad noise
    assert case.answer["achieved_magnitude_noise"] == pytest.approx(expected / 0.5, abs=2e-3)
    assert 1.5 < case.answer["achieved_magnitude_noise"] < 6.0  # the nominal 3x, within the mapping's factor 2
    seen = []

    class Stub:
        report = {"top_effect": "none", "top_group": [], "confidence": "none", "noise_floor_urad": 0.5,
                  "how_far": {"closure": 0.0}, "ranking": [], "where": {"concentrated": []},
                  "collinearity": {"absorbed_by_baseline": {}}, "undetectable": []}

    def spy(*args, **kwargs):
        seen.append((args, kwargs))
        return Stub()

    row = run_case(case, spy)
    assert len(seen) == 1 and not seen[0][1]  # one call, no keyword arguments
    (measurement,) = seen[0][0]  # exactly one positional argument: the measurement
    assert isinstance(measurement, Measurement) and measurement.metadata == {}
    assert "sensor_scale" not in json.dumps(measurement.extras, default=str)
    assert row["effect"] == "sensor_scale" and row["correct"] is False


def test_diagnose_command_writes_report_and_rejects_bad_file(tmp_path, none_case, capsys):
    data = tmp_path / "curves.csv"
    write_measurement(data, none_case.measurement)
    out = tmp_path / "run"
    assert cli.main(["diagnose", str(data), "--out", str(out), "--quiet", "--model-stiffness", "closed-form"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert REQUIRED_KEYS <= set(report)
    assert report["baseline"]["model"] == "consistent"  # the calibration commands' default since session 28
    assert report["top_effect"] in {"none", *[r["effect"] for r in report["ranking"]]}
    # the benchmark's blind file has no sidecar presets: the model-form floor says so
    assert report["model_form_floor"]["reason"].startswith("not available: no true values")
    for row in report["ranking"]:
        assert ROW_KEYS <= set(row) and len(row["heldout_rms_before_urad"]) == 3
    for name in ("report.md", "residual.png", "strata.png", "heldout.png"):
        assert (out / name).stat().st_size > 1000
    bad = tmp_path / "bad.csv"
    bad.write_text("point,time_s,leg\n1,0,0\n")
    capsys.readouterr()
    assert cli.main(["diagnose", str(bad), "--out", str(tmp_path / "bad_run")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "lacks required column" in err
    assert not (tmp_path / "bad_run").exists()
    short = tmp_path / "short.csv"
    measurement = read_measurement(data)
    import dataclasses
    write_measurement(short, dataclasses.replace(measurement, point=measurement.point[:10], time=measurement.time[:10],
                                                 leg=measurement.leg[:10], inputs=measurement.inputs[:10],
                                                 angles=measurement.angles[:10], extras={}, metadata={}))
    assert cli.main(["diagnose", str(short), "--out", str(tmp_path / "short_run")]) == 2
    assert "at least 20" in capsys.readouterr().err


def test_benchmark_command_tiny_grid_survives_a_failed_case_and_resumes(tmp_path, monkeypatch, capsys):
    """One case of each kind the benchmark scores (a library effect, none, an effect outside
    the library) at 10x noise. A case that raises is listed and the command exits 1 with the
    others' figures; the finished cases are kept in DIR/cases and a rerun computes only the
    failed one."""
    import flexcal.validation.diagnosis.benchmark as bench

    out = tmp_path / "bench"
    # --workers 0: the cases run in this process, where the monkeypatched failure applies
    # (the executor's worker processes are tested in tests/test_scale.py)
    # --no-null: the trajectory's null (three more `none` diagnoses first) is tested in test_diagnose_chain
    # --model second-order: the baseline's model is not this test's subject and the default (the
    # consistent model) takes ~2x as long per case (the default's diagnosis: test_diagnose_command_*)
    command = ["diagnose-benchmark", "--grid", "tiny", "--effects", "drift,none,sensor_interpolation", "--out",
               str(out), "--quiet", "--workers", "0", "--no-null", "--model", "second-order"]
    measure = bench.benchmark_measurement

    def none_runs_out_of_memory(effect_id, *args, **kwargs):
        if effect_id == "none":
            raise RuntimeError("PARDISO error -2: not enough memory")
        return measure(effect_id, *args, **kwargs)

    monkeypatch.setattr(bench, "benchmark_measurement", none_runs_out_of_memory)
    assert cli.main(command) == 1
    first = json.loads((out / "report.json").read_text())
    assert list(first["failures"]) == ["none 0x seed 0"] and "not enough memory" in first["failures"]["none 0x seed 0"]
    assert [r["effect"] for r in first["rows"]] == ["drift", "sensor_interpolation"]
    assert len(list((out / "cases").glob("*.json"))) == 2

    def only_none(effect_id, *args, **kwargs):
        assert effect_id == "none", f"{effect_id} was finished already and must not be run again"
        return measure(effect_id, *args, **kwargs)

    monkeypatch.setattr(bench, "benchmark_measurement", only_none)
    assert cli.main(command) == 0
    report = json.loads((out / "report.json").read_text())
    answers = json.loads((out / "answers.json").read_text())
    assert [a["effect"] for a in answers] == ["drift", "none", "sensor_interpolation"]
    assert report["failures"] == {}
    assert report["rows"][0] == first["rows"][0] and report["rows"][2] == first["rows"][1]
    summary = report["summary"]
    assert summary["confusion"]["drift"] == {"drift": 1}
    assert summary["false_alarm_rate_none"] == 0.0
    # outside the library: no confident claim of a library effect, and the place named
    assert summary["out_of_library_no_confident_claim"] == 1.0 and summary["out_of_library_where_named"] == 1.0
    # 3x the noise: the level this summary figure counts
    assert summary["detection_at_achieved_3x_or_more"] == 1.0 and answers[0]["achieved_magnitude_noise"] > 3.0
    for name in ("diagnosis_confusion.png", "diagnosis_detection.png", "diagnosis_closure.png"):
        assert (out / name).stat().st_size > 1000


def _designed_trajectory(folder):
    """A small ``flexcal design`` trajectory (41 postures from 300 candidates: 4 legs of up to
    11 after the zero posture; the model without its inadequacy weight, seconds)."""
    assert cli.main(["design", "--model", "second-order",
                     "--points", "41", "--candidates", "300", "--model-stiffness", "closed-form",
                     "--inadequacy", "none", "--out", str(folder), "-q"]) == 0
    return folder / "trajectory.csv"


def test_benchmark_measures_every_case_along_a_given_trajectory(tmp_path, monkeypatch, capsys):
    """``diagnose-benchmark --trajectory``: every case's measurement is the design's
    trajectory twice (legs numbered on in the second cycle), the report names the file and
    its hash, and the case ids differ from the standard trajectory's. The diagnosis is a
    stub here (the real one on designed data: the next test and docs/diagnosis.md)."""
    import flexcal.validation.diagnosis.diagnose as diagnose
    from flexcal.validation.diagnosis.benchmark import repeated_trajectory, trajectory_digest
    from flexcal.validation.prototype.scenario import read_trajectory

    trajectory = _designed_trajectory(tmp_path / "design")
    inputs, leg = read_trajectory(trajectory)
    seen = []

    class Stub:
        report = {"top_effect": "none", "top_group": [], "confidence": "none", "noise_floor_urad": 0.5,
                  "how_far": {"closure": 0.0}, "ranking": [], "where": {"concentrated": [], "structure": []},
                  "collinearity": {"absorbed_by_baseline": {}}, "undetectable": []}

    def stub(measurement, **_):
        seen.append(measurement)
        return Stub()

    monkeypatch.setattr(diagnose, "run_diagnosis", stub)
    out = tmp_path / "bench"
    command = ["diagnose-benchmark", "--grid", "tiny", "--effects", "drift,none", "--workers", "0", "-q", "--no-null"]
    assert cli.main([*command, "--trajectory", str(trajectory), "--out", str(out)]) == 0
    expected_inputs, expected_leg = repeated_trajectory(2, (inputs, leg))
    assert len(seen) == 2 and expected_leg.max() == 2 * leg.max() == 8
    for measurement in seen:
        np.testing.assert_allclose(measurement.inputs, expected_inputs, rtol=0, atol=1e-12)  # [m]
        np.testing.assert_array_equal(measurement.leg, expected_leg)
    report = json.loads((out / "report.json").read_text())
    digest = trajectory_digest(inputs, leg)
    assert report["trajectory"] == {"kind": "file", "file": str(trajectory), "sha256": digest, "n_points": 41,
                                    "n_legs": 4}
    assert f"sha256 {digest}" in (out / "report.md").read_text()
    cases = [json.loads(p.read_text()) for p in sorted((out / "cases").glob("*.json"))]
    assert {c["spec"]["trajectory"] for c in cases} == {digest}
    assert {c["answer"]["trajectory"] for c in cases} == {digest}
    # the standard trajectory: other case ids (no "trajectory" key in the spec), 153 points
    assert cli.main([*command, "--out", str(tmp_path / "standard")]) == 0
    standard = {p.name for p in (tmp_path / "standard" / "cases").glob("*.json")}
    assert len(standard) == 2 and not standard & {p.name for p in (out / "cases").glob("*.json")}
    assert seen[-1].n_points == 153
    assert json.loads((tmp_path / "standard" / "report.json").read_text())["trajectory"]["kind"] == "standard"
    # a trajectory too short for the diagnosis is refused before any case runs
    short = tmp_path / "short.csv"
    short.write_text("\n".join(trajectory.read_text().splitlines()[:6]) + "\n")
    capsys.readouterr()
    assert cli.main([*command, "--trajectory", str(short), "--out", str(tmp_path / "short")]) == 2
    assert "at least 20" in capsys.readouterr().err and len(seen) == 4


def test_diagnose_reads_a_measurement_on_a_designed_trajectory(tmp_path, capsys):
    """``flexcal design`` -> ``flexcal truth --trajectory`` -> ``flexcal diagnose --data``
    (analytic prototype, 0.5 urad noise): the legs are the design's (one held-out fold per
    leg), the noise floor is the sensor's, and since one pass of a designed trajectory
    measures each posture in one leg only, the command warns that the held-out scores
    extrapolate (docs/diagnosis.md, Designed trajectory)."""
    trajectory = _designed_trajectory(tmp_path / "design")
    truth = tmp_path / "truth"
    assert cli.main(["truth", "--scenario", "table1", "--provider", "analytic", "--noise-urad", "0.5",
                     "--trajectory", str(trajectory), "--out", str(truth), "-q"]) == 0
    data = truth / "curves.csv"
    assert read_measurement(data).leg.max() == 4
    capsys.readouterr()
    out = tmp_path / "diagnosis"
    assert cli.main(["diagnose", "--data", str(data), "--out", str(out), "--model-stiffness", "closed-form"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["n_points"] == 41 and report["heldout"]["unit"] == "leg" and report["heldout"]["n_folds"] == 4
    assert report["heldout"]["share_not_repeated"] > 0.5  # the warning threshold of diagnose (above it the note is printed)
    assert "extrapolate" in capsys.readouterr().err
    # the noise floor: 0.5 urad within what the structure adds (as on the standard trajectory: 0.45..0.8)
    assert 0.45 <= report["noise_floor_urad"] <= 0.8
    assert REQUIRED_KEYS <= set(report)
    # one measurement, named once
    assert cli.main(["diagnose", str(data), "--data", str(tmp_path / "other.csv"), "--out",
                     str(tmp_path / "two")]) == 2
    assert "give one" in capsys.readouterr().err


# Detection at >= 3x noise that the full FEM grid reached with the consistent baseline (the
# default since session 28; docs/diagnosis.md "Issue 28 results (session 28)"; again 72 in session 29
# with step_loss's own starts): 72 of its 78 cases
# (0.923, the goal 0.90 met by 0.023; the second-order baseline in sessions 22 and 27: 71; session
# 4's grid without the measurement chain's effects: 59 of 66). A rerun can flip marginal cases
# (another BLAS build moves a baseline fit), so the test allows two binomial standard errors of a
# rate over 78 cases, 2 sqrt(0.923 (1 - 0.923) / 78) = 0.060: floor 0.863, 68 of 78 (0.872) passes, 4
# more misses than measured; 5 or more is a regression of the diagnosis, not run-to-run scatter.
FEM_FULL_GRID_DETECTION, FEM_FULL_GRID_N_AT_3X = 72 / 78, 78


@pytest.mark.slow
def test_full_benchmark_grid_on_the_fem_prototype(tmp_path):
    """The full grid on the FEM prototype (136 cases; session 28, the consistent baseline: ~89 min on 2
    workers with a warm FEM cache, ~20 min of it beside a pytest run; session 22, second-order: 46 min): the goals of
    issue #7 that are met (false alarms on none, closure) and the detection figure the grid
    reached, each asserted. Runs its cases on both cores (--workers 2): run it alone."""
    import math

    from flexcal.validation.effects.library import EFFECT_IDS

    out = tmp_path / "bench"
    assert cli.main(["diagnose-benchmark", "--grid", "full", "--provider", "fem", "--workers", "2", "--out", str(out),
                     "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    goals = report["summary"]["goals"]
    assert goals["false_alarms_none"]["met"] and goals["closure_median"]["met"], goals
    strong = [r for r in report["rows"] if r["effect"] in EFFECT_IDS and r["magnitude_noise"] >= 3.0]
    assert len(strong) == FEM_FULL_GRID_N_AT_3X  # the same grid as the recorded figure
    p, n = FEM_FULL_GRID_DETECTION, FEM_FULL_GRID_N_AT_3X
    floor = p - 2 * math.sqrt(p * (1 - p) / n)
    detected = goals["detection_at_3x"]["measured"]
    assert detected >= floor, (f"detection at >= 3x noise {detected:.3f} ({sum(r['correct'] for r in strong)} of {n}) "
                               f"< {floor:.3f}: the recorded {p:.3f} minus two binomial standard errors")


@pytest.mark.slow  # a 153-point truth and a diagnosis with step_loss's ~900 starts per fit
def test_step_loss_placed_on_the_readme_design(provider):
    """Blind case step_loss 3x seed 0 on the README design measured twice (analytic prototype;
    the FEM grid's case on the same design, docs/diagnosis.md "Issue 28 results (session 29)"):
    from the five fixed starts alone a fold's fit stopped at a wrong place of the step, and creep
    won (held-out closure 0.36 against step_loss's 0.30, measured 2026-11-29). The term's own
    starts (``ModelTerm.starts``) find it."""
    from pathlib import Path

    from flexcal.validation.prototype.scenario import read_trajectory

    design = read_trajectory(Path(__file__).parent / "data" / "table1_design_k41_drives.csv")
    case = benchmark_measurement("step_loss", 3.0, 0, provider, trajectory=design)
    report = run_diagnosis(case.measurement, rng=0).report
    assert "step_loss" in (report["top_group"] or [report["top_effect"]]), report["ranking"][:3]


def test_step_loss_found_when_its_leg_is_held_out(provider):
    """Blind case step_loss 3x seed 2 (analytic prototype): the lost step falls in a leg that
    one fold holds out; before the weak prior on the nonlinear terms' parameters the fit
    without that leg ran off (held-out closure -48) and thermal won. Goals of issue #7:
    the right effect and >= 70 % of the gap closed."""
    case = benchmark_measurement("step_loss", 3.0, 2, provider)
    report = run_diagnosis(case.measurement, rng=0).report
    assert report["top_effect"] == "step_loss", report["ranking"][:3]
    assert report["ranking"][0]["closure"] >= 0.70  # issue #7's goal: >= 70 % of the gap closed (docstring)
