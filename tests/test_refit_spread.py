"""Refits on perturbed data widen the error bars where the misfit valley is curved
(calibration.refit_spread), and only there."""

import argparse

import numpy as np
import pytest

from flexcal.calibration.estimation import Prior, estimate
from flexcal.calibration.refit_spread import nonlinear_excess, null_edge, with_refit_spread

SIGMA = 0.01  # the noise of the toy problems [residual units]
POINTS = np.linspace(-1.0, 1.0, 40)


def _fit(model, truth, prior_std, seed=0):
    """MAP fit with the sandwich's bookkeeping (coordinates given) of data = model(truth) + noise."""
    data = model(np.asarray(truth)[None])[0] + np.random.default_rng(seed).normal(scale=SIGMA, size=POINTS.size * 3)

    def residuals_on(measured):
        return lambda X: model(X) - measured.reshape(-1)

    prior = Prior(mean=np.full(len(truth), 0.5), std=np.full(len(truth), prior_std))
    coordinates = np.column_stack([POINTS, POINTS ** 2, np.zeros_like(POINTS)])
    fit = estimate(residuals_on(data), prior, noise=SIGMA, coordinates=coordinates)
    fitted = model(fit.x[None])[0].reshape(-1, 3)
    return fit, residuals_on, fitted


def _linear(X):
    """Three parameters entering linearly (three angles a point)."""
    X = np.atleast_2d(X)
    basis = np.stack([np.ones_like(POINTS), POINTS, POINTS ** 2])  # (3, n)
    return np.repeat(X @ basis, 3, axis=1) * np.tile([1.0, 0.5, 0.25], POINTS.size)


def _curved(X):
    """A banana valley: the data see a + 4 (b - 1/2)^2 sharply and b only through a weak slope,
    so when the noise is redrawn the estimate moves along the parabola: b by its (linear) weak
    bar, and a with it by far more than a's linear bar, which sees only the sharp combination."""
    X = np.atleast_2d(X)
    a, b = X[:, :1], X[:, 1:2]
    sharp = np.repeat((a + 4.0 * (b - 0.5) ** 2) * np.ones_like(POINTS), 3, axis=1)
    weak = np.repeat(0.02 * b * POINTS, 3, axis=1)
    return sharp + weak


def test_null_edge_is_the_white_largest_eigenvalues_99th_percentile():
    """Fresh white draws (another seed than the edge's own) pass the edge in about 1 % of
    cases, for a small and a large rank; for the large rank it sits near the asymptotic
    Marchenko-Pastur edge (1 + sqrt(r/K))^2, above it as a 99th percentile should; 1.1 s."""
    rng = np.random.default_rng(7)
    for rank, n in ((5, 30), (45, 30)):
        edge = null_edge(rank, n)
        x = rng.normal(size=(4000, n, rank))
        gram = x @ x.transpose(0, 2, 1) if n < rank else x.transpose(0, 2, 1) @ x
        passed = np.mean(np.linalg.eigvalsh(gram / n)[:, -1] > edge)
        # expected 0.01 (measured 0.015 and 0.0115: the edge's own 2000-draw estimate adds ~0.3 %);
        # binomial sd 0.0016 over 4000 draws: the band [0.004, 0.025] is > 3 sd around both
        assert 0.004 < passed < 0.025
    asymptotic = (1 + np.sqrt(45 / 30)) ** 2
    assert asymptotic < null_edge(45, 30) < 1.3 * asymptotic  # measured 1.10x: finite-size fluctuation above the edge


def test_a_linear_problem_is_not_widened():
    """Linear in its parameters with a weak prior: the refits spread as the linear covariance
    says, no direction passes the edge, and the error bars are the sandwich's, unchanged."""
    fit, residuals_on, fitted = _fit(_linear, [0.4, 0.6, 0.5], prior_std=10.0)
    widened = with_refit_spread(fit, residuals_on, fitted, 30, seed=3)
    assert widened.refit_spread.eigenvalues.size == 0
    np.testing.assert_array_equal(widened.covariance, fit.covariance)


def test_a_curved_valley_widens_the_bar_along_it_and_never_narrows_one():
    """The banana: the refits spread along the parabola much more than the linear covariance
    allows (largest whitened eigenvalue far above the edge: measured 1083 against 1.58); the bar
    of a widens (the sandwich's 0.032 -> 0.046, the refits' own spread of a 0.038), no bar
    narrows, and the added covariance is positive semi-definite."""
    fit, residuals_on, fitted = _fit(_curved, [0.3, 0.52], prior_std=10.0)
    widened = with_refit_spread(fit, residuals_on, fitted, 30, seed=3)
    spread = widened.refit_spread
    assert spread.eigenvalues.size >= 1 and spread.eigenvalues.max() > 2 * spread.edge  # a real excess, not a tail
    assert widened.std[0] > 1.3 * fit.std[0]  # a's bar widened (measured x1.45); 1.3: a third of that margin
    assert np.all(widened.std >= fit.std * (1 - 1e-12))  # no bar narrows (round-off only)
    assert np.linalg.eigvalsh(spread.added).min() > -1e-12 * np.abs(spread.added).max()  # PSD up to round-off


def test_nonlinear_excess_adds_the_excess_of_a_known_spread():
    """Refits spread exactly 16x the linear variance along one whitened direction (and 1x in
    the others): the added covariance is 15x that direction's linear variance, nothing else."""
    linear = np.diag([4.0, 1.0, 0.25])
    u = np.array([1.0, 0.0, 0.0])
    # deviations +-4 sigma along u, +-1 sigma along the others: second moments 16, 1, 1 (whitened)
    deviations = np.array([[8.0, 0, 0], [-8.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 0.5], [0, 0, -0.5]])
    deviations = np.repeat(deviations, 50, axis=0)  # 300 refits: the edge (1 + sqrt(3/300))^2 = 1.2
    scale = np.sqrt(len(deviations) / (2 * 50))  # so that the mean square per direction is as stated
    added, eigenvalues, edge = nonlinear_excess(deviations * scale, np.zeros(3), linear)
    np.testing.assert_allclose(eigenvalues, [16.0], rtol=1e-12)  # exact arithmetic up to round-off
    np.testing.assert_allclose(added, 15.0 * 4.0 * np.outer(u, u), atol=1e-9)  # 15 x the linear variance 4


def test_refits_default_by_model_and_checked():
    """--refits: the consistent model's default 30, the others' 0, --method paper none, and a
    single refit (no covariance) refused."""
    from flexcal.validation.cli.options import refits_option

    def args(**kw):
        return argparse.Namespace(**{"refits": None, "method": "map", "model": "second-order", **kw})
    assert refits_option(args(model="consistent")) == 30
    assert refits_option(args()) == 0
    assert refits_option(args(refits=5)) == 5
    assert refits_option(args(method="paper", model="consistent")) == 0
    for bad in (-1, 1):
        with pytest.raises(ValueError, match="--refits"):
            refits_option(args(refits=bad))
