"""Profile-likelihood bars of base combinations (calibration.profile_bars): widened where
the misfit valley is curved, left alone where the problem is linear, never narrowed."""

import argparse

import numpy as np
import pytest

from flexcal.calibration.estimation import Prior, estimate
from flexcal.calibration.profile_bars import one_sigma_crossing, profile_factor, with_profile_bars

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


def test_the_one_sigma_crossing_of_the_probes():
    """Linear in sqrt(dP) between probes from (0, 0): a quadratic profile (dP = k^2) crosses
    at k = 1 wherever it is probed; a flat side that never reaches 1 gives its last k; f is the
    larger side."""
    assert one_sigma_crossing([(2.0, 4.0)]) == pytest.approx(1.0, rel=1e-12)  # exact arithmetic
    assert one_sigma_crossing([(6.0, 36.0)]) == pytest.approx(1.0, rel=1e-12)  # exact arithmetic
    # between (6, 0.25) and (18, 4): sqrt 0.5 -> 2, one at 6 + 12 x 0.5 / 1.5 = 10; exact arithmetic
    assert one_sigma_crossing([(2.0, 0.04), (6.0, 0.25), (18.0, 4.0)]) == pytest.approx(10.0, rel=1e-12)
    assert one_sigma_crossing([(2.0, 0.1), (6.0, 0.5)]) == 6.0  # the box ended below one standard error
    assert one_sigma_crossing([]) == 0.0
    assert profile_factor([((2.0, 4.0),), ((2.0, 0.04), (6.0, 0.25), (18.0, 4.0))]) == 10.0


def test_a_linear_problem_is_not_widened():
    """Linear: the first probe a side (2 linear standard errors) rises by 4, so each side
    crosses one standard error at k = 1 and stops; f = 1, and the bar stays the sandwich's
    (which is at least the linear one here: the noise is given and the fitted discrepancy
    adds to it), so the covariance is unchanged."""
    fit, residuals = _fit(_linear, [0.4, 0.6, 0.5])
    combinations = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, -1.0]])
    profiled = with_profile_bars(fit, residuals, combinations)
    # 1e-3: the constrained fits' tolerance on the rise (trf's 1e-10 on a ~120 cost)
    np.testing.assert_allclose(profiled.profile_bars.factors, [1.0, 1.0], rtol=1e-3)
    for sides in profiled.profile_bars.probes:
        assert [[k for k, _ in side] for side in sides] == [[2.0], [2.0]]
        assert all(rise == pytest.approx(4.0, rel=1e-3) for side in sides for _, rise in side)  # the same tolerance
    np.testing.assert_array_equal(profiled.covariance, fit.covariance)


def test_a_curved_valley_widens_the_pinned_looking_combination():
    """Near the vertex of the valley the linear bar of a is the sharp one; its profile is flat
    towards lower a (measured: rise 0.79 at 2 linear standard errors, 3.02 at 6), so it crosses
    one standard error at 2.53 of them, and a's bar becomes that (2.3x the sandwich's); no bar
    narrows and the added covariance is positive semi-definite."""
    fit, residuals = _fit(_valley, [0.3, 0.5])
    profiled = with_profile_bars(fit, residuals, np.array([[1.0, 0.0]]))
    factor = profiled.profile_bars.factors[0]
    assert factor > 2.0  # measured 2.53; a linear problem gives 1
    linear = np.sqrt(fit.gauss_newton_covariance[0, 0])
    assert profiled.std[0] == pytest.approx(factor * linear, rel=1e-9)  # the bar of c is f linear ones; round-off
    assert profiled.std[0] > 2.0 * fit.std[0]  # and wider than the sandwich's (measured 2.3x)
    assert np.all(profiled.std >= fit.std * (1 - 1e-12))  # no bar narrows (round-off only)
    added = profiled.profile_bars.added
    assert np.linalg.eigvalsh(added).min() > -1e-12 * np.abs(added).max()  # PSD up to round-off


def test_profile_bars_follow_the_declared_sensor_noise_unless_given():
    """--profile-bars / --no-profile-bars as given; by default on exactly when the run declares
    sensor noise (--noise-urad > 0, else the sidecar's sensors.noise_urad), off for a noise-free
    or undeclared measurement (its cost and too-wide bars there, docs/calibration.md 6); off for
    --method paper whatever is asked."""
    from flexcal.validation.cli.options import profile_option

    def args(**kw):
        return argparse.Namespace(**{"profile_bars": None, "method": "map", "noise_urad": None, **kw})
    noisy, quiet = {"sensors": {"noise_urad": [0.0, 0.5, 0.0]}}, {"sensors": {"noise_urad": [0.0, 0.0, 0.0]}}
    assert profile_option(args(), {}) is False  # nothing declared (a real file without a sidecar)
    assert profile_option(args(), quiet) is False
    assert profile_option(args(), noisy) is True  # one channel's noise is enough
    assert profile_option(args(noise_urad=0.5), quiet) is True  # the option overrides the sidecar
    assert profile_option(args(noise_urad=0.0), noisy) is False
    assert profile_option(args(profile_bars=False), noisy) is False
    assert profile_option(args(profile_bars=True), {}) is True
    assert profile_option(args(profile_bars=True, method="free"), {}) is True
    assert profile_option(args(profile_bars=True, method="paper"), noisy) is False
    assert profile_option(args(method="paper"), noisy) is False


def test_the_sidecars_stated_noise_is_read_in_one_place():
    """``sidecar.stated_sensor_noise_urad``: the per-channel noise a sidecar states, None when it
    states none (the profile bars' default, the compensation bench and the form floor each say
    what that means)."""
    from flexcal.validation.sidecar import stated_sensor_noise_urad

    for metadata in ({}, {"sensors": None}, {"sensors": {}}, {"sensors": {"offset_urad": [1.0, 0.0, 0.0]}}):
        assert stated_sensor_noise_urad(metadata) is None
    stated = stated_sensor_noise_urad({"sensors": {"noise_urad": [0.0, 0.5, 0.25]}})
    assert stated.tolist() == [0.0, 0.5, 0.25]


def test_verify_profiles_a_noisy_scenario_by_default(tmp_path, monkeypatch):
    """The command line reaches run_verify with the profile on for a scenario with --noise-urad,
    off without it, and off with --no-profile-bars (the settings seen by a stub run_verify)."""
    from flexcal.validation import cli
    from flexcal.validation.runs import verify as runs_verify

    seen = []

    class Stop(Exception):
        pass

    def fake_run_verify(measurement, space, settings, **kwargs):
        seen.append(settings.profile)
        raise Stop  # the fit itself is tested elsewhere

    monkeypatch.setattr(runs_verify, "run_verify", fake_run_verify)
    base = ["verify", "--scenario", "table1", "--provider", "analytic", "--model", "paper", "--method", "map",
            "--out", str(tmp_path / "v"), "--quiet"]
    for extra, expected in ((["--noise-urad", "0.5"], True), ([], False),
                            (["--noise-urad", "0.5", "--no-profile-bars"], False)):
        seen.clear()
        assert cli.main(base + extra) != 0  # stopped by the stub
        assert seen == [expected]
