"""`flexcal verify` end to end on a small configuration (the full run is the README's main job)."""

import json

import numpy as np
import pytest

from flexcal.validation import cli


def test_verify_writes_the_report_with_the_required_keys(tmp_path):
    """The paper's method (Sobol screening + improved PSO), tiny settings."""
    out = tmp_path / "run"
    status = cli.main(["verify", "--scenario", "table1", "--provider", "analytic", "--model", "second-order",
                       "--model-stiffness", "closed-form",
                       "--method", "paper", "--sobol-n", "16", "--particles", "48", "--iterations", "12", "--out", str(out), "-q"])
    assert status == 0
    report = json.loads((out / "report.json").read_text())
    for key in ("parameters", "fit_rms_urad", "n_evaluations", "paper_comparison"):
        assert key in report, key
    timings = json.loads((out / "timings.json").read_text())  # wall-clock times apart from the results
    assert "wall_s" not in report and timings["wall_s"] > 0 and set(timings["timings_s"]) == {"sobol", "pso"}
    row = {r["name"]: r for r in report["parameters"]}["D3.x0"]
    assert set(row) >= {"name", "unit", "preset", "identified", "abs_error", "rel_error"}
    # even this tiny swarm + polish must land near the preset D3 initial position (0.40 mm):
    # the analytic prototype shares the model's chain physics; 20 um is 2 % of the range
    assert row["abs_error"] < 0.02
    figures = {r["figure"] for r in report["paper_comparison"]}
    assert figures == {"initial_position_max_abs_error_um", "clearance_max_abs_error_mm",
                       "hysteresis_max_rel_error_pct", "other_max_rel_error_pct", "orientation_fit_max_urad"}
    assert all({"paper", "ours", "beats_paper", "ours_identifiable", "not_identifiable"} <= set(r)
               for r in report["paper_comparison"])
    # D1/D2 are compressed throughout the standard trajectory: their clearances are named as
    # not observable on this mount (not counted as identified or missed)
    clearance = {r["figure"]: r for r in report["paper_comparison"]}["clearance_max_abs_error_mm"]
    assert set(clearance["not_observable"]) == {"D1.CL", "D2.CL"}
    assert not {"D1.CL", "D2.CL"} & set(clearance["not_identifiable"])
    assert report["n_evaluations"] > 16 * 47  # Sobol (N (d + 2)) + swarm, all counted
    for name in ("report.md", "fit.png", "convergence.png", "residuals.png"):
        assert (out / name).is_file(), name


@pytest.mark.slow
def test_full_table1_run_on_the_fem_prototype(tmp_path):
    # the README's main job (MAP of all 45 sources with a cross-validated prior; the consistent
    # model since session 21, its fits started at the second-order estimate; the FEM-informed
    # second-order model before) on the standard trajectory. Measured 2026-11-23: see
    # docs/verification-table1.md; the bounds are the paper's figures where the mount can show
    # them, and 2x headroom on the fit for fTetWild's mesh-to-mesh scatter (the seed fixes one draw)
    out = tmp_path / "table1"
    assert cli.main(["verify", "--scenario", "table1", "--out", str(out), "-q"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["model"].endswith("(--model consistent)")  # the calibration default (cli.options)
    # issue 24's noise-free goal for the fit's largest error; measured 0.0082 (RMS 0.0016) urad,
    # the second-order model 1.55 (docs/model.md, "Session 21")
    assert report["fit_max_urad"] <= 0.1
    # issue 28's band [0.5, 2] is for noisy runs. Noise-free the bars carry the model-error budget
    # (0.07 urad at the estimate) against a 0.0016 urad fit, so they are conservative: measured
    # 0.235 over 20 with the offsets' Cartesian chart (session 23); the polar chart's 0.83 over 17
    # came from one row at 3.3, the others <= 0.42 (docs/calibration.md "Session 23"). Since the
    # noise floor of session 26 (the fit no longer hangs on round-off) and the quadratic dimension
    # terms by default: 1.14 over 19 (1.55 with the linear terms). Bars not too narrow (<= 2) and
    # not another 1.5x wider than the widest measured (>= 0.15)
    assert 0.15 <= report["base_parameters"]["z_rms"] <= 2.0
    figures = {r["figure"]: r for r in report["paper_comparison"]}
    assert figures["initial_position_max_abs_error_um"]["ours_identifiable"] < 2.7  # beats the paper's Table 1
    rows = {r["name"]: r for r in report["parameters"]}
    assert rows["D3.CL"]["abs_error"] < 0.004  # [mm]
    assert report["fit_rms_urad"] < 6.0  # the closed-form model left 5.1 urad (session 1)
    # issue 24's time goal is a warm figure; the first run may have built FEM segments (the
    # prototype's, and the estimate's geometry for the model-error budget: session 21 saw that
    # fail the bound once), so the same job again times a warm cache
    assert cli.main(["verify", "--scenario", "table1", "--out", str(out), "-q", "--force"]) == 0
    again = json.loads((out / "report.json").read_text())
    assert again["fit_rms_urad"] == report["fit_rms_urad"]  # the same job: seeded, single-threaded estimate
    wall_s = json.loads((out / "timings.json").read_text())["wall_s"]
    assert wall_s < 120  # goal 60 s warm on an idle machine; 2x for a loaded CI runner


def _analytic_verify(tmp_path, *extra):
    out = tmp_path / "run"
    status = cli.main(["verify", "--provider", "analytic", "--model", "second-order",
                       "--model-stiffness", "closed-form", "--noise-urad", "0.5",
                       "--out", str(out), "-q", *extra])
    assert status == 0
    return json.loads((out / "report.json").read_text()), out


def test_map_recovers_the_drive_sources_with_honest_error_bars(tmp_path):
    """MAP of all 45 sources on the analytic prototype (0.5 urad noise, standard trajectory):
    every value has an error bar; the initial positions beat the paper's 2.7 um; the z-scores
    of the sources identified alone have an RMS inside the issue's honesty band [0.5, 2]
    (measured 1.12 / 1.32 / 1.10 on seeds 1-3). The regrouped base combinations of chain
    dimensions are not held to it: they absorb the model-form error of the analytic prototype
    (exact kinematics, backlash operator) and miss by 4-24 standard errors (docs/calibration.md)."""
    report, out = _analytic_verify(tmp_path, "--scenario", "table1")
    assert report["method"] == "map"
    rows = {r["name"]: r for r in report["parameters"]}
    assert all(r["std_error"] is not None and r["std_error"] > 0 for r in rows.values())
    # every source has a z-score but an offset direction the data do not determine (its bar is "open")
    assert all(r["z_score"] is not None for r in rows.values() if "undetermined" not in r)
    assert {"D1.x0", "D2.x0", "D3.x0"} <= set(report["identifiable"])
    assert max(rows[f"D{i}.x0"]["abs_error"] for i in (1, 2, 3)) * 1e3 < 2.7  # [um], paper Table 1
    # the honesty band (docstring; measured 1.10-1.32)
    assert report["n_z_scores"] >= 4 and 0.5 <= report["z_rms_identifiable"] <= 2.0
    cv = report["estimation"]["cross_validation"]
    assert cv["n_folds"] == 3 and report["estimation"]["prior_scale"] in cv["scales"]
    # D1/D2 are compressed throughout: their clearance/hysteresis rows say why, not "miss"
    assert set(report["not_observable"]) == {"D1.CL", "D1.mu", "D2.CL", "D2.mu"}
    assert "not observable on this mount" in report["not_observable"]["D1.CL"]
    for name in ("report.md", "fit.png", "residuals.png", "calibration.png"):
        assert (out / name).is_file(), name


def test_paper_mount_shows_every_drive_row(tmp_path):
    """The built-in `paper` scenario (centre of gravity at O_C): all three drives pass through
    their clearance on the standard trajectory, so no Table 1 row is hidden."""
    report, _ = _analytic_verify(tmp_path, "--scenario", "paper", "--prior-scale", "1")
    assert report["not_observable"] == {}
    assert all(r["shown"] for r in report["paper_comparison"])
    assert "S2" in report["point_class"]  # points with a drive in its clearance zone (Fig. 12)


def test_verify_refuses_underdetermined_data(tmp_path, capsys):
    from flexcal.validation.measurements import Measurement, write_measurement

    n = 10  # 30 observations < 45 sources
    measurement = Measurement(point=np.arange(1, n + 1), time=np.arange(n) * 2.0, leg=np.ones(n, int),
                              inputs=np.zeros((n, 3)), angles=np.zeros((n, 3)), extras={}, metadata={})
    write_measurement(tmp_path / "few.csv", measurement)
    for command in (["verify"], ["identify", "--sources", "all"]):
        status = cli.main([*command, "--data", str(tmp_path / "few.csv"), "--model", "second-order",
                           "--model-stiffness", "closed-form",
                           "--out", str(tmp_path / "o"), "-q"])
        assert status == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "fewer than the 45" in err[0], err
        assert not (tmp_path / "o").exists()


def test_design_beats_the_standard_trajectory_and_drives_truth(tmp_path):
    out = tmp_path / "design"
    assert cli.main(["design", "--model", "second-order",
                     "--points", "41", "--candidates", "300", "--model-stiffness", "closed-form",
                     "--inadequacy", "none", "--out", str(out), "-q"]) == 0
    report = json.loads((out / "report.json").read_text())
    designed, standard = report["designed"], report["standard_trajectory"]
    # 41 designed postures against the 77 of the standard trajectory: D-criterion and rank higher
    assert designed["log_det_information"] > standard["log_det_information"]
    assert designed["rank"] > standard["rank"]
    lines = (out / "trajectory.csv").read_text().splitlines()
    assert lines[0] == "point,leg,xa1_mm,xa2_mm,xa3_mm" and len(lines) == 42
    assert cli.main(["truth", "--scenario", "table1", "--provider", "analytic", "--trajectory",
                     str(out / "trajectory.csv"), "--out", str(tmp_path / "t"), "-q"]) == 0
    truth = (tmp_path / "t" / "curves.csv").read_text().splitlines()
    assert len(truth) == 42


def test_identify_goes_through_the_one_pipeline_with_error_bars(tmp_path):
    """identify --method map: the nine drive sources by MAP through run_verify (the pipeline
    verify and compensate use), each with a standard error; on the analytic prototype (the
    model's own physics, 0.5 urad noise) D3's initial position, which the standard
    trajectory sees well, lands within 4 standard errors of its preset (|z| <= 4: a 1-in-15,000
    miss for an honest Gaussian error bar)."""
    out = tmp_path / "id"
    status = cli.main(["identify", "--scenario", "table1", "--provider", "analytic", "--noise-urad", "0.5",
                       "--model", "second-order",
                           "--model-stiffness", "closed-form", "--method", "map", "--prior-scale", "2",
                       "--out", str(out), "-q"])
    assert status == 0
    report = json.loads((out / "report.json").read_text())
    assert report["summary"]["method"] == "map"
    assert sorted(report["selected"]) == sorted(f"D{i}.{s}" for s in ("x0", "CL", "mu") for i in (1, 2, 3))
    rows = {r["name"]: r for r in report["parameters"]}
    assert all(rows[n]["std_error"] is not None and rows[n]["std_error"] > 0 for n in report["selected"])
    assert rows["D3.x0"]["z_score"] is not None and abs(rows["D3.x0"]["z_score"]) <= 4.0  # 1-in-15,000 for an honest error bar (docstring)
    assert rows["L1.w"]["std_error"] is None and not rows["L1.w"]["was_identified"]  # not chosen: stays nominal
    assert not (out / "convergence.png").exists()  # no swarm, no convergence picture


def test_error_bars_stay_honest_with_a_deliberately_imperfect_model(tmp_path):
    """The paper's model (no second-order terms) on the analytic prototype, seeds 1-2: its form
    error (model at the true values 2.5-3.7 urad RMS from the data, residual 0.77 urad after the
    fit absorbs most of it) biases the drive sources and the drive-gain combinations. Both the
    8 sources identified alone and the 12 base parameters must have a pooled z RMS in the
    issue's honesty band [0.5, 2]. Measured on the same fits: Gauss-Newton bars with the AR(1)
    noise 1.27 and 18.7 (the base parameters fail); Matern-discrepancy bars 0.33 and 2.24 (the
    sources fail); Matern + quadratic-polynomial discrepancy 0.56 and 2.13 (the base parameters
    fail by 0.13). Each source has one error bar: a source identified alone is its own row in
    the base table, with the same standard error."""
    z, z_base = [], []
    for seed in ("1", "2"):
        report, _ = _analytic_verify(tmp_path / seed, "--scenario", "table1", "--seed", seed, "--no-second-order")
        z += [r["z_score"] for r in report["parameters"] if r["identifiable"]]
        z_base += [r["z_score"] for r in report["base_parameters"]["rows"] if r["z_score"] is not None]
        rows = {r["name"]: r for r in report["parameters"]}
        table = {r["label"]: r for r in report["base_parameters"]["rows"]}
        for name in report["base_parameters"]["pure"]:  # same error and truth: same z only with the same bar
            # one number computed twice from the same covariance entry: only rounding may differ
            assert np.isclose(table[name]["z_score"], rows[name]["z_score"], rtol=1e-6), name
    assert len(z) >= 8 and len(z_base) >= 12
    assert 0.5 <= float(np.sqrt(np.mean(np.square(z)))) <= 2.0  # the honesty band
    assert 0.5 <= float(np.sqrt(np.mean(np.square(z_base)))) <= 2.0  # the same band for the base parameters
