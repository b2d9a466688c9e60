"""Profile-likelihood bars of base combinations (calibration.profile_bars): widened where
the misfit valley is curved, left alone where the problem is linear, never narrowed."""

import argparse

import numpy as np
import pytest

from flexcal.calibration.estimation import Prior, estimate
from flexcal.calibration.profile_bars import profile_factor, with_profile_bars

SIGMA = 0.01  # the noise of the toy problems [residual units]
POINTS = np.linspace(-1.0, 1.0, 40)


def _fit(model, truth, seed=0):
    """MAP fit (weak prior, noise given, sandwich bookkeeping) of model(truth) + noise."""
    data = model(np.asarray(truth)[None])[0] + np.random.default_rng(seed).normal(scale=SIGMA, size=POINTS.size * 3)

    def residuals(X):
        return model(X) - data

    prior = Prior(mean=np.full(len(truth), 0.5), std=np.full(len(truth), 10.0))
    coordinates = np.column_stack([POINTS, POINTS ** 2, np.zeros_like(POINTS)])
    return estimate(residuals, prior, noise=SIGMA, coordinates=coordinates), residuals


def _linear(X):
    """Three parameters entering linearly (three angles a point)."""
    X = np.atleast_2d(X)
    basis = np.stack([np.ones_like(POINTS), POINTS, POINTS ** 2])  # (3, n)
    return np.repeat(X @ basis, 3, axis=1) * np.tile([1.0, 0.5, 0.25], POINTS.size)


def _valley(X):
    """The data see a + 4 (b - 1/2)^2 sharply and b only through a weak slope: at the vertex
    the Jacobian pins a alone, but a lower a is met by b leaving the vertex, paid for only by
    the weak slope's misfit: a's profile is flat on that side."""
    X = np.atleast_2d(X)
    a, b = X[:, :1], X[:, 1:2]
    sharp = np.repeat((a + 4.0 * (b - 0.5) ** 2) * np.ones_like(POINTS), 3, axis=1)
    weak = np.repeat(0.02 * b * POINTS, 3, axis=1)
    return sharp + weak


def test_profile_factor_is_the_largest_lower_bound_of_the_probes():
    """A probe inside one standard error (rise < 1) bounds f by its k; outside, by k / sqrt(rise)."""
    assert profile_factor([(2.0, 4.0)]) == pytest.approx(1.0, rel=1e-12)  # linear: rise k^2; exact arithmetic
    # k = 2 and 6 inside one standard error bound f by 2 and 6; 18 at rise 4.5 by 18 / sqrt(4.5); exact arithmetic
    assert profile_factor([(2.0, 0.25), (6.0, 0.5), (18.0, 4.5)]) == pytest.approx(18.0 / np.sqrt(4.5), rel=1e-12)
    assert profile_factor([]) == 1.0


def test_a_linear_problem_is_not_widened():
    """Linear: every probe rises by k^2 (the linear prediction), so each side stops at k = 2
    and no combination is widened; the covariance is the sandwich's, unchanged."""
    fit, residuals = _fit(_linear, [0.4, 0.6, 0.5])
    combinations = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, -1.0]])
    profiled = with_profile_bars(fit, residuals, combinations)
    np.testing.assert_array_equal(profiled.profile_bars.factors, [1.0, 1.0])
    for probes in profiled.profile_bars.probes:
        assert [k for k, _ in probes] == [2.0, 2.0]
        # the linear rise 4 at two standard errors, to the fit's own tolerance (1e-3: trf's 1e-10 on a ~120 cost)
        assert all(rise == pytest.approx(4.0, rel=1e-3) for _, rise in probes)
    np.testing.assert_array_equal(profiled.covariance, fit.covariance)


def test_a_curved_valley_widens_the_pinned_looking_combination():
    """Near the vertex of the valley the linear bar of a is the sharp one; its profile is flat
    towards lower a (measured: rise 0.79 at 2 linear standard errors, 3.02 at 6; the box ends
    before 18), so its bar widens 3.45x; no bar narrows and the added covariance is positive
    semi-definite."""
    fit, residuals = _fit(_valley, [0.3, 0.5])
    profiled = with_profile_bars(fit, residuals, np.array([[1.0, 0.0]]))
    factor = profiled.profile_bars.factors[0]
    assert factor > 2.5  # measured 3.45 (6 / sqrt(3.02)); a linear problem gives 1
    assert profiled.std[0] == pytest.approx(fit.std[0] * factor, rel=1e-9)  # the bar of c itself scales by f
    assert np.all(profiled.std >= fit.std * (1 - 1e-12))  # no bar narrows (round-off only)
    added = profiled.profile_bars.added
    assert np.linalg.eigvalsh(added).min() > -1e-12 * np.abs(added).max()  # PSD up to round-off


def test_profile_bars_default_by_model():
    """--profile-bars: on for the consistent model, off for the others and for --method paper,
    as given when given."""
    from flexcal.validation.cli.options import profile_option

    def args(**kw):
        return argparse.Namespace(**{"profile_bars": None, "method": "map", "model": "second-order", **kw})
    assert profile_option(args(model="consistent")) is True
    assert profile_option(args()) is False
    assert profile_option(args(profile_bars=True)) is True
    assert profile_option(args(model="consistent", profile_bars=False)) is False
    assert profile_option(args(method="paper", model="consistent")) is False
