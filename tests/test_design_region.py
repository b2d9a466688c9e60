"""Designs for where the mount is used (issue #28 item 2): candidates in the standard trajectory's
input box or the hull of its postures, the I-criterion (prediction variance), fixed postures, and
the "drives" criterion (A-optimal on the drive sources' expected variances, each over its paper
Table 1 figure squared: trace(M^-1 A), A diagonal on the drive sources, greedy_i_optimal's exchange)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from flexcal.calibration.design import (candidate_inputs, d_criterion, design_trajectory, figure_weights,
                                        greedy_d_optimal, greedy_i_optimal, i_criterion)

BOX = np.array([1.0e-3, 1.0e-3, 0.65e-3])  # [m] strokes like table1's standard trajectory
WORKSPACE = np.array([1e-3, 5e-3, 3e-3])  # [rad]


def _jacobian(inputs):
    """A toy model whose signatures grow with the posture (k, 3) -> (3 k, 6)."""
    u = np.asarray(inputs, float) / BOX
    rows = np.stack([u, u ** 2, np.ones_like(u)], axis=-1)
    return np.concatenate([rows, rows ** 3], axis=-1).reshape(-1, 6) * 1e-5


def test_candidates_fill_the_box_and_the_hull_and_nothing_outside():
    box = candidate_inputs(BOX, 4000, "box", rng=0)
    hull = candidate_inputs(BOX, 4000, "hull", rng=0)
    # exact bounds of the draw: |x| <= box and sum |x/a| <= 1 (Dirichlet weights sum to at most 1)
    assert np.all(np.abs(box) <= BOX) and np.all(np.sum(np.abs(hull) / BOX, axis=1) <= 1.0)
    # uniform: each box octant holds 1/8 of 4000 (binomial sd ~21: 5 sd), the hull's mean |x/a| is 1/4
    octants = np.unique((box > 0) @ np.array([1, 2, 4]), return_counts=True)[1]
    assert octants.size == 8 and np.all(np.abs(octants - 500) < 105), octants
    np.testing.assert_allclose(np.mean(np.abs(hull) / BOX, axis=0), 0.25, atol=0.01)  # sd of the mean ~0.003
    with pytest.raises(ValueError, match="region"):
        candidate_inputs(BOX, 10, "workspace")


def test_i_optimal_predicts_better_than_d_optimal_and_is_a_local_optimum():
    """On the same candidates the I-optimal selection has the lower mean prediction variance
    over the postures to predict, the D-optimal the larger log det (each wins its own criterion)."""
    rng = np.random.default_rng(3)
    candidates = candidate_inputs(BOX, 300, "box", rng)
    J = _jacobian(candidates).reshape(300, 3, 6) / 0.5e-6
    P = _jacobian(candidate_inputs(BOX, 200, "box", rng)) / 0.5e-6
    A, precision = P.T @ P / 200, np.full(6, 12.0)
    d_pick, _ = greedy_d_optimal(J, precision, 10)
    i_pick, value = greedy_i_optimal(J, precision, 10, A)
    W_d, W_i = J[d_pick].reshape(-1, 6), J[i_pick].reshape(-1, 6)
    assert i_criterion(W_i, precision, A) <= i_criterion(W_d, precision, A)
    assert d_criterion(W_d, precision) >= d_criterion(W_i, precision)
    # the returned value is the criterion of the selection (same formula, rounding only)
    assert value == pytest.approx(i_criterion(W_i, precision, A), rel=1e-9)
    for position in range(10):  # no single swap improves it (exchange converged)
        for c in range(300):
            trial = i_pick.copy()
            trial[position] = c
            # 1e-9 relative: the exchange's own threshold
            assert i_criterion(J[trial].reshape(-1, 6), precision, A) >= value * (1 - 1e-9)


def test_fixed_postures_come_first_and_the_design_adds_the_rest():
    fixed = np.array([[0, 0, 0], [BOX[0], 0, 0], [-BOX[0], 0, 0], [0, BOX[1], 0], [0, 0, -BOX[2]]])
    design = design_trajectory(_jacobian, np.eye(3), WORKSPACE, fixed, n_points=12, n_candidates=200,
                               prior_precision=np.full(6, 12.0), rng=1, region="hull", box=BOX,
                               fixed_inputs=fixed, fixed_leg=np.array([0, 1, 1, 2, 3]), points_per_leg=4)
    np.testing.assert_array_equal(design.inputs[:5], fixed)
    # inside the hull; 1e-12: the rounding of x / a on the fixed postures at the vertices
    assert design.inputs.shape == (12, 3) and np.all(np.sum(np.abs(design.inputs) / BOX, axis=1) <= 1 + 1e-12)
    np.testing.assert_array_equal(design.leg, [0, 1, 1, 2, 3, 4, 4, 4, 4, 5, 5, 5])
    with pytest.raises(ValueError, match="fixed postures leave none"):
        design_trajectory(_jacobian, np.eye(3), WORKSPACE, fixed, n_points=5, n_candidates=20,
                          prior_precision=np.full(6, 12.0), fixed_inputs=fixed)


def test_design_cli_keeps_the_standard_postures_and_stays_in_their_hull(tmp_path):
    """flexcal design --keep-standard 13 --region hull --criterion I: the 13-point standard
    trajectory first (its postures and legs), then 28 I-optimal postures inside the hull of the
    77-point standard trajectory's postures; the options are in report.json, and report.md says
    which postures were kept and that none was avoided (--inadequacy none)."""
    import json

    from flexcal.model.trajectory import standard_trajectory
    from flexcal.validation import cli
    from flexcal.validation.prototype.scenario import load_scenario

    out = tmp_path / "design"
    assert cli.main(["design", "--model", "second-order",
                     "--points", "41", "--candidates", "200", "--model-stiffness", "closed-form",
                     "--inadequacy", "none", "--region", "hull", "--criterion", "I", "--keep-standard", "13",
                     "--out", str(out), "-q"]) == 0
    rows = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    mechanism = load_scenario("table1").space.mechanism
    kept, box = standard_trajectory(mechanism, n_points=13), standard_trajectory(mechanism).amplitudes
    assert rows.shape == (41, 5)
    # the CSV holds mm with 9 decimals: 1e-9 mm (1e-12 m) is its rounding
    np.testing.assert_allclose(rows[:13, 2:] * 1e-3, kept.inputs, atol=1e-12)
    np.testing.assert_array_equal(rows[:13, 1], kept.leg)
    # inside the hull; 1e-9: the CSV's rounding relative to the ~1 mm strokes
    assert np.all(np.sum(np.abs(rows[13:, 2:] * 1e-3) / box, axis=1) <= 1 + 1e-9)
    report = json.loads((out / "report.json").read_text())
    assert (report["region"], report["criterion_name"], report["keep_standard"]) == ("hull", "I", 13)
    assert (report["kept"]["n_kept"], report["kept"]["n_designed"]) == (13, 28) and report["avoided"] is None
    text = (out / "report.md").read_text()  # the report says which postures were kept and that none was avoided
    assert "Postures kept: the first 13 are the 13-point standard trajectory" in text and "No posture avoided" in text


def test_figure_weights_weigh_only_the_named_sources_by_range_over_figure_squared():
    names = ("L1.w", "D1.x0", "D1.CL", "D1.mu", "H1.k")
    spans = np.array([1e-4, 1e-3, 4e-4, 0.2, 5.0])
    A = figure_weights(names, spans, {"D1.x0": 2.7e-6, "D1.CL": 2e-5, "D1.mu": 0.013})
    assert np.count_nonzero(A - np.diag(np.diag(A))) == 0  # diagonal
    # (range / figure)^2; default rel 1e-6: float rounding only
    assert np.diag(A) == pytest.approx([0.0, (1e-3 / 2.7e-6) ** 2, (4e-4 / 2e-5) ** 2, (0.2 / 0.013) ** 2, 0.0])
    # so trace(M^-1 A) is the sum of (standard error [SI] / figure)^2 for unit-box variances M^-1
    variances = np.array([1.0, 1e-4, 4e-4, 1e-2, 1.0])
    expected = sum((np.sqrt(v) * s / f) ** 2 for v, s, f in zip(variances[1:4], spans[1:4], (2.7e-6, 2e-5, 0.013)))
    assert np.trace(np.diag(variances) @ A) == pytest.approx(expected)  # default rel 1e-6: rounding only
    with pytest.raises(ValueError, match="not among"):
        figure_weights(names, spans, {"D2.x0": 2.7e-6})
    with pytest.raises(ValueError, match="> 0"):
        figure_weights(names, spans, {"D1.x0": 0.0})


def test_drive_figures_are_the_paper_table1_figures_in_si():
    """x0 2.7 um, CL 0.02 mm, mu 1.3 % of its value at the design point (validation.runs.verify.PAPER_TABLE1)."""
    from flexcal.model.parameters import DRIVE_SOURCE_NAMES
    from flexcal.validation.cli.design import drive_figures

    names = ("L1.w",) + DRIVE_SOURCE_NAMES
    lower, span = np.zeros(len(names)), np.full(len(names), 2.0)
    space = SimpleNamespace(names=names, from_unit=lambda eta: lower + span * eta)
    eta = np.full(len(names), 0.25)  # every value 0.5 [SI]
    figures = drive_figures(space, eta)
    assert set(figures) == set(DRIVE_SOURCE_NAMES)
    for name, figure in figures.items():  # default rel 1e-6: unit conversion only
        assert figure == pytest.approx({"x0": 2.7e-6, "CL": 2e-5, "mu": 0.013 * 0.5}[name.split(".")[1]])


def test_drives_design_narrows_the_drive_bars_more_than_the_d_design():
    """On the same candidates, the "drives" design has a lower trace(M^-1 A) over the weighed
    sources than the D-optimal one (fails if the criterion is ignored: the same design), and the
    D design the larger log det (each wins its own criterion)."""
    names = ("a", "b", "c", "d", "e", "f")
    A = figure_weights(names, np.ones(6), {"b": 0.5, "e": 0.1})
    precision = np.full(6, 12.0)
    common = dict(n_points=15, n_candidates=300, prior_precision=precision, rng=4, region="box", box=BOX)
    d_design = design_trajectory(_jacobian, np.eye(3), WORKSPACE, np.zeros((1, 3)), criterion="D", **common)
    a_design = design_trajectory(_jacobian, np.eye(3), WORKSPACE, np.zeros((1, 3)), criterion="drives",
                                 variance_weights=A, **common)
    W_d, W_a = _jacobian(d_design.inputs) / 0.5e-6, _jacobian(a_design.inputs) / 0.5e-6
    trace_d, trace_a = i_criterion(W_d, precision, A), i_criterion(W_a, precision, A)
    # 10 %: clear of a tie (the criterion ignored gives the D design, ratio 1); measured 0.83 (0.190 / 0.228)
    assert trace_a < 0.9 * trace_d, (trace_a, trace_d)
    assert d_criterion(W_d, precision) >= d_criterion(W_a, precision)
    with pytest.raises(ValueError, match="variance_weights"):
        design_trajectory(_jacobian, np.eye(3), WORKSPACE, np.zeros((1, 3)), criterion="drives", **common)


def test_design_cli_criterion_drives_writes_its_criterion(tmp_path):
    """flexcal design --criterion drives: report.json names it and gives the drive sources' trace for
    the design and the standard trajectory; report.md's criterion line and figure rows say it."""
    import json

    from flexcal.validation import cli

    out = tmp_path / "design"
    assert cli.main(["design", "--model", "second-order",
                     "--points", "41", "--candidates", "200", "--model-stiffness", "closed-form",
                     "--inadequacy", "none", "--criterion", "drives", "--keep-standard", "13",
                     "--out", str(out), "-q"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["criterion_name"] == "drives" and report["criterion"].startswith("A-optimal on the drive sources")
    drives = report["drives_criterion"]
    assert drives["designed"]["trace"] > 0 and drives["standard_trajectory"]["trace"] > 0
    text = (out / "report.md").read_text()
    assert "Criterion: A-optimal on the drive sources" in text and "(drives criterion)" in text
