"""MAP estimation, standard errors, base parameters, D-optimal design (calibration/)."""

from __future__ import annotations

import numpy as np
import pytest

from flexcal.calibration.base_parameters import base_parameters, pivoted_qr
from flexcal.calibration.design import design_quality, greedy_d_optimal, order_postures
from flexcal.calibration.estimation import estimate, held_out_folds, posterior, uniform_prior
from flexcal.calibration.identifiability import analyze_jacobian
from flexcal.calibration.pipeline import check_determined


def _linear_problem(seed: int, m: int = 60, d: int = 4, sigma: float = 0.01):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, d))
    truth = rng.uniform(0.2, 0.8, size=d)
    y = A @ truth + rng.normal(size=m) * sigma
    return A, truth, y, sigma, (lambda X: np.atleast_2d(X) @ A.T - y)


def test_map_of_a_linear_model_is_the_closed_form_posterior_mean():
    A, _, y, sigma, residuals = _linear_problem(0)
    prior = uniform_prior(A.shape[1], 0.3)
    fit = estimate(residuals, prior, noise=sigma)
    information = A.T @ A / sigma**2 + np.diag(prior.precision)
    expected = np.linalg.solve(information, A.T @ y / sigma**2 + prior.precision * prior.mean)
    # trf converges to ftol/xtol 1e-10 on a quadratic: 1e-7 of the unit box is far above that
    np.testing.assert_allclose(fit.x, expected, atol=1e-7)
    # the covariance of a linear model is exact: (J^T J / sigma^2 + Lambda)^-1; the
    # finite-difference Jacobian of a linear map is exact to round-off (1e-9 relative)
    np.testing.assert_allclose(fit.covariance, np.linalg.inv(information), rtol=1e-6)


def test_z_scores_of_a_linear_model_are_standard_normal():
    """With the noise estimated from the residual, (estimate - truth) / std over many
    independent problems has RMS 1: 400 z-values give an RMS within 1 +- 0.12 (its standard
    deviation is ~ 1/sqrt(2 * 400) = 0.035; 0.12 is 3.4 of those)."""
    z = []
    for seed in range(100):
        A, truth, _, sigma, residuals = _linear_problem(seed)
        fit = estimate(residuals, uniform_prior(A.shape[1], np.inf), point_size=1)
        z.extend((fit.x - truth) / fit.std)
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert abs(rms - 1.0) < 0.12, rms  # 3.4 standard deviations of the RMS (docstring)


def test_noise_estimate_recovers_the_noise():
    """sigma^2 = RSS / (m - p_eff): on 2,000 residuals its relative standard deviation is
    ~ 1/sqrt(2 * 2000) = 1.6 %; 5 % is 3 of those."""
    A, _, _, sigma, residuals = _linear_problem(1, m=2000, sigma=0.02)
    fit = estimate(residuals, uniform_prior(A.shape[1], 1.0), point_size=1)
    assert fit.noise == pytest.approx(sigma, rel=0.05)  # 3 standard deviations of the noise estimate (docstring)
    assert fit.p_eff == pytest.approx(A.shape[1], abs=0.05)  # data dominate a weak prior: p_eff -> d


def test_a_source_the_data_cannot_see_stays_at_its_prior():
    A, _, _, sigma, _ = _linear_problem(2)
    A = np.hstack([A, np.zeros((A.shape[0], 1))])  # a fifth source with no effect at all
    y = A @ np.array([0.3, 0.6, 0.4, 0.7, 0.9])
    prior = uniform_prior(5, 1.0)
    fit = estimate(lambda X: np.atleast_2d(X) @ A.T - y, prior, noise=sigma)
    assert fit.x[4] == pytest.approx(0.5, abs=1e-9)  # the prior mean: no data pull
    assert fit.std[4] == pytest.approx(prior.std[4], rel=1e-9)  # and the prior's std
    free = posterior(A, sigma, uniform_prior(5, np.inf))[2]
    assert np.isinf(free[4]) and np.all(np.isfinite(free[:4]))  # without a prior: unbounded, and said so


def test_duplicated_parameter_is_regrouped_into_the_base():
    rng = np.random.default_rng(3)
    u, v = rng.normal(size=(2, 50))
    W = np.column_stack([u, v, 2.0 * u]) * 100.0  # column 2 is twice column 0
    result = base_parameters(W, ("a", "b", "c"))
    assert set(result.base) == {"c", "b"} and result.regrouped == ("a",)
    k = result.base.index("c")
    # beta_c = x_c + 0.5 x_a: W_a = W_c / 2 exactly; QR round-off is ~1e-15 relative
    assert result.coefficients[k, 0] == pytest.approx(0.5, abs=1e-12)
    assert result.labels[k] == "c + 0.5 a"
    # the data only see the combination: two x with the same beta give the same W x
    x1, x2 = np.array([0.2, 0.3, 0.4]), np.array([0.6, 0.3, 0.2])
    # QR round-off in the coefficients (see above)
    np.testing.assert_allclose(result.values(x1, ("a", "b", "c")), result.values(x2, ("a", "b", "c")), atol=1e-12)
    np.testing.assert_allclose(W @ x1, W @ x2, atol=1e-12)  # entries ~1e2: round-off, measured 6e-14 (was 1e-9)


def test_pivot_ties_go_to_the_lower_index():
    rng = np.random.default_rng(4)
    u = rng.normal(size=30)
    W = np.column_stack([rng.normal(size=30) * 0.1, u, u]) * 1e3  # columns 1 and 2 identical
    result = base_parameters(W, ("p", "q", "r"))
    assert "q" in result.base and "r" in result.regrouped
    _, R, pivots = pivoted_qr(W)
    assert list(pivots[:1]) == [1]
    # Householder QR: R[0, 0] = +-|column| to round-off
    np.testing.assert_allclose(np.abs(R[0, 0]), np.linalg.norm(W[:, 1]), rtol=1e-12)


def test_identifiability_takes_a_tall_jacobian_without_a_square_u():
    """20,000 postures x 3 angles: a full SVD's U alone would be 28.8 GB; the thin one is
    what the analysis needs."""
    rng = np.random.default_rng(5)
    J = rng.normal(size=(60_000, 45))
    report = analyze_jacobian(J, [f"p{i}" for i in range(45)], noise=1.0)
    assert report.rank == 45
    s = np.linalg.svd(J, compute_uv=False)
    # thin vs values-only SVD of a well-conditioned J: round-off, measured 1e-15 (was 1e-10)
    np.testing.assert_allclose(report.singular_values, s, rtol=1e-13)


def test_underdetermined_data_are_refused():
    with pytest.raises(ValueError, match="fewer than the 45"):
        check_determined(14, 45)  # 42 observations < 45 unknowns
    check_determined(15, 45)  # 45 observations: determined


def test_held_out_folds_are_whole_legs():
    leg = np.array([0, 1, 1, 1, 2, 2, 3, 3, 3])
    folds = held_out_folds(leg)
    assert [f.tolist() for f in folds] == [[1, 2, 3], [4, 5], [6, 7, 8]]
    blocks = held_out_folds(np.array([0] + [1] * 9), n_folds=5)
    assert sum(len(b) for b in blocks) == 10 and all(np.all(np.diff(b) == 1) for b in blocks)


def test_greedy_d_optimal_beats_random_and_exchange_is_a_local_optimum():
    rng = np.random.default_rng(6)
    candidates = rng.normal(size=(300, 3, 6))
    precision = np.full(6, 1e-2)
    chosen, value = greedy_d_optimal(candidates, precision, 12)
    for seed in range(20):  # no random 12-subset may beat it
        pick = np.random.default_rng(seed).choice(300, 12, replace=False)
        random_value = design_quality(candidates[pick].reshape(-1, 6), precision).d_criterion
        assert random_value < value
    # M built by rank-3 updates vs rebuilt: round-off in log det (measured 0)
    assert value == pytest.approx(design_quality(candidates[chosen].reshape(-1, 6), precision).d_criterion, rel=1e-10)
    # no single swap improves it (what the exchange passes stop on), checked by brute force
    for position in range(12):
        for other in range(0, 300, 7):
            trial = chosen.copy()
            trial[position] = other
            # the exchange stops when no swap gains > 1e-9 in log det (design.py), plus round-off
            assert design_quality(candidates[trial].reshape(-1, 6), precision).d_criterion <= value + 1e-8


def test_order_postures_visits_each_once_from_the_nearest():
    points = np.array([[3.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    assert order_postures(points, np.ones(3)).tolist() == [1, 2, 0]


def test_correlated_misfit_inflates_the_error_bars():
    """A smooth misfit (a model-form error) has a lag-1 autocorrelation near 1; white noise
    near 0. The AR(1) factor (1 + rho)/(1 - rho) follows."""
    from flexcal.calibration.estimation import residual_autocorrelation

    t = np.linspace(0.0, 1.0, 300)
    smooth = np.sin(2 * np.pi * t)
    assert residual_autocorrelation(smooth, point_size=1) > 0.99 * 0.95  # clipped at 0.95
    white = np.random.default_rng(7).normal(size=3000)
    # white noise: |rho| ~ 1/sqrt(3000) = 0.018; 0.06 is 3.3 of those
    assert residual_autocorrelation(white, point_size=1) < 0.06
    A, truth, y, sigma, _ = _linear_problem(8, m=300)
    drift = 0.05 * smooth  # a smooth error 5x the noise on top of the data
    plain = estimate(lambda X: np.atleast_2d(X) @ A.T - y - drift, uniform_prior(4, np.inf), point_size=1,
                     correlated=False)
    inflated = estimate(lambda X: np.atleast_2d(X) @ A.T - y - drift, uniform_prior(4, np.inf), point_size=1)
    # drift 5x the noise: rho ~ 25/26, inflation ~26; measured 18.6 and std 4.3x (was > 5 and > 2x)
    assert inflated.inflation > 10.0 and np.all(inflated.std > 3.0 * plain.std)


def test_many_legs_are_merged_into_five_folds():
    leg = np.concatenate([[0], np.repeat(np.arange(1, 8), 11)])  # a designed trajectory: 7 legs of 11
    folds = held_out_folds(leg)
    assert len(folds) == 5
    assert sorted(np.concatenate(folds).tolist()) == list(range(1, 78))  # every point but the start, once
    assert all(len(set(leg[f])) in (1, 2) for f in folds)  # whole legs only


def test_the_narrowest_scale_within_one_standard_error_is_chosen():
    """The one-standard-error rule: a wider prior is chosen only when its held-out RMS beats
    the narrowest's by more than the best score's standard error."""
    from flexcal.calibration.estimation import one_standard_error_choice

    scores = np.array([1.57, 1.54, 2.17])  # session 16's flip: scale 2 better by 0.03
    assert one_standard_error_choice(scores, np.array([0.05, 0.05, 0.05])) == 0  # 0.03 < one error
    assert one_standard_error_choice(scores, np.array([0.01, 0.01, 0.01])) == 1  # 0.03 > one error
    assert one_standard_error_choice(scores, np.zeros(3)) == 1  # no spread: the lowest score


def test_the_held_out_error_comes_from_the_folds_spread():
    from flexcal.calibration.estimation import _held_out_rms_and_error

    same = _held_out_rms_and_error(np.array([4.0, 4.0, 4.0]), np.array([4, 4, 4]))
    assert same == (1.0, 0.0)  # equal folds: RMS 1 exactly, no spread
    rms, error = _held_out_rms_and_error(np.array([2.0, 4.0, 6.0]), np.array([4, 4, 4]))
    assert rms == pytest.approx(1.0)  # pooled 12 / 12
    # fold mean squares 0.5, 1, 1.5: std 0.5, / sqrt(3), halved for the RMS (delta method)
    assert error == pytest.approx(0.5 / np.sqrt(3) / 2.0, rel=1e-12)  # 1e-12: round-off


def test_prior_held_directions_keep_finite_bars_when_the_data_dwarf_the_prior():
    """A noise-free fit's noise is the model's (0.003 urad on the consistent model's main job):
    the data's information then lies ~1e13-1e16 above the prior's. Every direction the prior
    holds has a finite posterior variance, exactly 1 / (s^2 + prior precision) along the data's
    right singular vectors for an isotropic prior; the normal equations' eigendecomposition
    declared such directions unseen (std inf) before session 21."""
    rng = np.random.default_rng(7)
    d = 5
    V, _ = np.linalg.qr(rng.normal(size=(d, d)))
    U, _ = np.linalg.qr(rng.normal(size=(40, d)))
    s = np.array([1e8, 3e7, 1e6, 1e-3, 0.0])  # two directions only the prior sees
    J = U @ np.diag(s) @ V.T
    prior = uniform_prior(d, 1.0)
    precision = prior.precision[0]
    sigma, p_eff, std = posterior(J, 1.0, prior)
    exact = V @ np.diag(1.0 / (s ** 2 + precision)) @ V.T
    assert np.all(np.isfinite(std))
    # the SVD's round-off on the small singular values is ~1e-16 x 1e8 / 3.5 ~ 3e-9 relative
    np.testing.assert_allclose(std, np.sqrt(np.diag(exact)), rtol=1e-6)
    # in the singular basis: the round-off of the largest entries (1/12) is ~1e-15 absolute, far
    # below the prior-held variances checked here (the data-held ones, ~1e-16, are below it)
    np.testing.assert_allclose(V.T @ sigma @ V, np.diag(1.0 / (s ** 2 + precision)), rtol=1e-6, atol=1e-12)
    # p_eff: the data's share of each direction, ~1 for the three the data see; round-off as above
    assert p_eff == pytest.approx(float(np.sum(s ** 2 / (s ** 2 + precision))), rel=1e-6)
