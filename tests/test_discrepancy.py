"""Model-discrepancy error bars (calibration.discrepancy): honest z-scores when the model
cannot fit the data, from the measurement, the model and its Jacobian only."""

import numpy as np
import pytest

from flexcal.calibration.discrepancy import (discrepancy_covariance, fit_discrepancy, model_error_factor,
                                             polynomial_features,
                                             sandwich_covariance)
from flexcal.calibration.estimation import estimate, uniform_prior

N_POINTS, N_PARAMS = 40, 6


def _linear_problem(rng, amplitude: float, noise: float = 1.0):
    """Postures c (n, 2) in the unit square; a linear model of smooth signatures (3 angles a
    point); data = model at a prior draw + a discrepancy drawn from a Matern process + noise."""
    c = rng.uniform(-1.0, 1.0, size=(N_POINTS, 2))
    features = np.stack([np.ones(N_POINTS), c[:, 0], c[:, 1], c[:, 0] * c[:, 1], c[:, 0] ** 2, c[:, 1] ** 2], 1)
    mixing = rng.normal(size=(3, N_PARAMS, N_PARAMS))
    J = np.einsum("nk,akd->nad", features, mixing).reshape(3 * N_POINTS, N_PARAMS) * 5.0
    truth = rng.uniform(0.0, 1.0, N_PARAMS)
    delta = np.linalg.cholesky(discrepancy_covariance(c, 1e-9, np.full(3, amplitude), 0.7)) @ rng.normal(
        size=3 * N_POINTS)
    y = J @ truth + delta + noise * rng.normal(size=3 * N_POINTS)
    return c, J, truth, y


def _z_scores(amplitude: float, n_draws: int, coordinates: bool) -> np.ndarray:
    z = []
    rng = np.random.default_rng(7)
    for _ in range(n_draws):
        c, J, truth, y = _linear_problem(rng, amplitude)
        fit = estimate(lambda X, J=J, y=y: X @ J.T - y, uniform_prior(N_PARAMS, 4.0),
                       coordinates=c if coordinates else None)
        z.extend((fit.x - truth) / fit.std)
    return np.asarray(z)


def test_discrepancy_error_bars_are_honest_where_gauss_newton_ones_are_not():
    """A smooth discrepancy 3x the noise: the Gauss-Newton bars (even with the AR(1) inflation)
    give z RMS well above 2; the discrepancy-sandwich bars stay within [0.6, 1.6]. 20 draws x 6
    parameters = 120 z-scores: the RMS of 120 standard normals is within 1 +- 0.15 at 2 sigma,
    and a misestimated discrepancy (a few hyperparameters from 120 rows) spreads it more."""
    honest = np.sqrt(np.mean(_z_scores(3.0, 20, coordinates=True) ** 2))
    naive = np.sqrt(np.mean(_z_scores(3.0, 20, coordinates=False) ** 2))
    # RMS of 120 honest z-scores: 1 +- 0.15 at 2 sigma, plus the spread of estimated hyperparameters
    assert 0.6 <= honest <= 1.6, honest
    # the honesty band ends at 2: the Gauss-Newton bars must be outside it here (measured > 2)
    assert naive > 2.0, naive


def test_white_noise_gives_back_the_gauss_newton_bars():
    """No discrepancy: over 5 draws the sandwich standard errors are the Gauss-Newton ones on
    average (geometric mean of the 30 ratios within 10 %; one draw's maximum-likelihood process
    may keep a chance amplitude of ~0.7 noise that widens some bars by up to 30 %, an average
    widening above 10 % would be a bias of the method)."""
    ratios = []
    for seed in range(3, 8):
        c, J, truth, y = _linear_problem(np.random.default_rng(seed), amplitude=0.0)
        fit = estimate(lambda X, J=J, y=y: X @ J.T - y, uniform_prior(N_PARAMS, 4.0), coordinates=c)
        ratios.extend(fit.std / np.sqrt(np.diag(fit.gauss_newton_covariance)))
    mean = float(np.exp(np.mean(np.log(ratios))))
    # no systematic widening: 10 % (docstring: one draw's chance process widens by up to 30 %)
    assert 0.9 <= mean <= 1.1, mean


def test_sandwich_is_the_posterior_when_the_data_error_is_the_weighting():
    """Sigma = sigma_w^2 I makes A (J^T Sigma J / sigma_w^4 + P) A = A (algebra)."""
    rng = np.random.default_rng(0)
    J, precision = rng.normal(size=(30, 4)), np.array([1.0, 2.0, 0.5, 3.0])
    A = np.linalg.inv(J.T @ J / 0.3 ** 2 + np.diag(precision))
    # an identity of the algebra: only rounding of a 4 x 4 inverse (condition ~10) separates them
    np.testing.assert_allclose(sandwich_covariance(A, J, 0.3, precision, 0.09 * np.eye(30)), A, rtol=1e-9)


def test_fit_discrepancy_recovers_noise_and_amplitude():
    """Pure data (no parameters to absorb it): noise 1 within a factor 1.5, and a process of
    amplitude 4 within a factor 3 (240 rows, one draw: a Matern amplitude and its length scale
    trade off on a bounded domain, only their ratio is estimated consistently (Zhang 2004), so
    the amplitude alone is loose; the noise is not)."""
    rng = np.random.default_rng(11)
    c = rng.uniform(-1.0, 1.0, size=(80, 2))
    y = np.linalg.cholesky(discrepancy_covariance(c, 1.0, np.full(3, 4.0), 0.7)) @ rng.normal(size=240)
    found = fit_discrepancy(-y, np.zeros((240, 1)), np.zeros(1), np.zeros(1), np.ones(1), c)
    # factor 1.5 for the noise, 3 for the amplitude: docstring (one draw, amplitude-length trade-off)
    assert 1 / 1.5 < found.noise < 1.5
    assert np.all((found.amplitude > 4.0 / 3.0) & (found.amplitude < 4.0 * 3.0)), found.amplitude  # see above


def test_design_never_offers_postures_where_the_model_is_known_to_be_off():
    """A toy design whose largest signatures sit where the model's expected error is largest
    (|angle| near the workspace edge): with max_inadequacy those candidates are avoided (never
    chosen, listed in Design.avoided); weighted by the inadequacy alone the D-criterion still
    picks them (a 3-noise model error only divides their information by ~10)."""
    from flexcal.calibration.design import design_trajectory

    workspace = np.array([1e-3, 5e-3, 3e-3])
    gain = np.eye(3)

    def jacobian(inputs):  # signatures grow with the posture: the corners inform most
        u = inputs / workspace
        rows = np.stack([u, u ** 2, np.ones_like(u)], axis=-1)  # (k, 3, 3)
        return np.concatenate([rows, rows ** 3], axis=-1).reshape(-1, 6) * 1e-5

    def inadequacy(inputs):  # [rad] the model is off by 3 noise beyond 60 % of the workspace
        return np.where(np.abs(inputs / workspace) > 0.6, 1.5e-6, 0.1e-6)

    kwargs = dict(n_points=12, n_candidates=300, noise=0.5e-6, prior_precision=np.full(6, 12.0),
                  inadequacy=inadequacy, rng=1)
    free = design_trajectory(jacobian, gain, workspace, np.zeros((5, 3)), **kwargs)
    kept = design_trajectory(jacobian, gain, workspace, np.zeros((5, 3)), max_inadequacy=1e-6, **kwargs)
    off = lambda inputs: np.any(np.abs(inputs / workspace) > 0.6, axis=1)  # noqa: E731
    assert np.any(off(free.inputs))
    assert not np.any(off(kept.inputs))
    assert kept.avoided.sum() == np.sum(off(kept.candidates)) > 0


def _quadratic_problem(rng, tau: float, noise: float = 1.0):
    """Like ``_linear_problem``, with the discrepancy a quadratic polynomial per angle whose
    coefficients are N(0, tau^2): the model's signatures are quadratics in the posture too, so
    part of it lies along the parameters' directions (a bias no residual shows) and the rest
    shows in the residual."""
    c = rng.uniform(-1.0, 1.0, size=(N_POINTS, 2))
    features = polynomial_features(c)
    mixing = rng.normal(size=(3, features.shape[1], N_PARAMS))
    J = np.einsum("nk,akd->nad", features, mixing).reshape(3 * N_POINTS, N_PARAMS) * 5.0
    truth = rng.uniform(0.0, 1.0, N_PARAMS)
    delta = (features @ rng.normal(scale=tau, size=(features.shape[1], 3))).reshape(-1)  # points major
    y = J @ truth + delta + noise * rng.normal(size=3 * N_POINTS)
    return c, J, truth, y


@pytest.mark.slow  # 20 estimates with two discrepancy fits each: ~150 s wall at load 10, ~25 s CPU
def test_quadratic_discrepancy_along_the_parameters_is_covered():
    """A quadratic discrepancy (coefficients 2 noise each, ~4 noise RMS) biases the estimates:
    with the polynomial part fitted jointly by marginal likelihood the z RMS is within
    [0.6, 1.6] (20 draws x 6 parameters = 120 z-scores: 1 +- 0.15 at 2 sigma, plus the spread of
    estimated hyper-parameters); the Gauss-Newton bars are far outside the issue's band (> 2),
    and the Matern part alone is less honest (its z RMS further from 1 in ratio: measured 0.64,
    too wide, where the polynomial part gives 0.98: a long Matern length scale extrapolates the
    amplitude it sees in the residual to the directions the parameters absorb)."""
    rng = np.random.default_rng(5)
    z_new, z_matern, z_gn, taus = [], [], [], []
    for _ in range(20):
        c, J, truth, y = _quadratic_problem(rng, tau=2.0)
        fit = estimate(lambda X, J=J, y=y: X @ J.T - y, uniform_prior(N_PARAMS, 4.0), coordinates=c)
        matern = fit_discrepancy(fit.residual, fit.jacobian, fit.x, fit.prior.mean, fit.prior.std, c,
                                 polynomial=False)
        cov = sandwich_covariance(fit.gauss_newton_covariance, fit.jacobian, fit.noise, fit.prior.precision,
                                  matern.covariance)
        z_new.extend((fit.x - truth) / fit.std)
        z_matern.extend((fit.x - truth) / np.sqrt(np.diag(cov)))
        z_gn.extend((fit.x - truth) / np.sqrt(np.diag(fit.gauss_newton_covariance)))
        taus.append(fit.discrepancy.as_dict()["polynomial_tau_urad"] / 1e6)  # as the report gives it
    rms = lambda z: float(np.sqrt(np.mean(np.square(z))))  # noqa: E731
    # RMS of 120 honest z-scores: 1 +- 0.15 at 2 sigma, plus the spread of estimated hyper-parameters
    assert 0.6 <= rms(z_new) <= 1.6, (rms(z_new), rms(z_matern), rms(z_gn))
    # the band ends at 2: the Gauss-Newton bars must be outside it here
    assert rms(z_gn) > 2.0, rms(z_gn)
    assert abs(np.log(rms(z_new))) < abs(np.log(rms(z_matern))), (rms(z_matern), rms(z_new))
    # tau is estimated within a factor 2 of the drawn 2 (median over the 20 draws; 10 x 3 coefficients a draw)
    assert 1.0 < float(np.median(taus)) < 4.0, taus


def test_polynomial_features_and_covariance():
    """Features 1, c, c^2, cross terms; the covariance is the Matern part + tau^2 Phi Phi^T per angle."""
    c = np.array([[0.5, -1.0, 2.0], [0.0, 1.0, -0.5]])
    phi = polynomial_features(c)
    assert phi.shape == (2, 10)
    np.testing.assert_array_equal(phi[0], [1, 0.5, -1, 2, 0.25, 1, 4, -0.5, 1.0, -2.0])  # exact arithmetic
    with_poly = discrepancy_covariance(c, 0.1, np.full(3, 0.2), 0.7, polynomial=3.0)
    without = discrepancy_covariance(c, 0.1, np.full(3, 0.2), 0.7)
    # one entry by hand: point 0 angle 1 against point 1 angle 1 differs by tau^2 phi_0 . phi_1
    assert np.isclose(with_poly[1, 4] - without[1, 4], 9.0 * phi[0] @ phi[1], rtol=1e-12)  # rounding only
    assert np.allclose(with_poly[1, 5], without[1, 5], rtol=1e-12)  # angles independent: no cross term


def _absorbed_problem(rng, n_samples: int = 8, spread: float = 0.3):
    """A form error the parameters absorb whole: delta = J w (no trace in the residual, which
    is white noise), w = w0 + spread |w0| xi per mount; the budget's samples are the same form
    error at n_samples other mounts (w0 + spread |w0| xi_k), the truth's at one more. w0 sets
    delta ~3 noise RMS."""
    c, J, truth, _ = _linear_problem(rng, amplitude=0.0)
    w0 = rng.normal(size=N_PARAMS)
    w0 *= 3.0 / np.sqrt(np.mean((J @ w0) ** 2))
    at = lambda: w0 + spread * np.sqrt(np.mean(w0 ** 2)) * rng.normal(size=N_PARAMS)  # noqa: E731
    samples = np.array([J @ at() for _ in range(n_samples)])
    y = J @ truth + J @ at() + rng.normal(size=3 * N_POINTS)
    return c, J, truth, y, samples


def test_model_error_budget_covers_a_form_error_the_fit_absorbs_whole():
    """delta in the range of J: the residual is white, so no residual-fitted discrepancy widens
    the bars (z RMS >> 2: the consistent model on FEM table1 had base parameters at 13-24 sigma,
    docs/calibration.md 6 session 16); the budget (the same model error sampled at other
    mounts, ``model_error``) makes them honest: z RMS within [0.6, 1.6] over 10 draws x 6
    parameters (1 +- 0.2 at 2 sigma for 60 honest z-scores, plus the spread of a second
    moment estimated from 8 samples; measured 0.88 with the budget, 7.5 without; ~16 s CPU)."""
    rng = np.random.default_rng(11)
    z_budget, z_without = [], []
    for _ in range(10):
        c, J, truth, y, samples = _absorbed_problem(rng)
        residuals = lambda X, J=J, y=y: X @ J.T - y  # noqa: E731
        with_budget = estimate(residuals, uniform_prior(N_PARAMS, 4.0), coordinates=c, model_error=samples)
        without = fit_discrepancy(with_budget.residual, with_budget.jacobian, with_budget.x, with_budget.prior.mean,
                                  with_budget.prior.std, c)
        cov = sandwich_covariance(with_budget.gauss_newton_covariance, with_budget.jacobian, with_budget.noise,
                                  with_budget.prior.precision, without.covariance)
        z_budget.extend((with_budget.x - truth) / with_budget.std)
        z_without.extend((with_budget.x - truth) / np.sqrt(np.diag(cov)))
    rms = lambda z: float(np.sqrt(np.mean(np.square(z))))  # noqa: E731
    # RMS of 60 honest z-scores: 1 +- 0.2 at 2 sigma, plus the spread of an 8-sample second moment
    assert 0.6 <= rms(z_budget) <= 1.6, (rms(z_budget), rms(z_without))
    # the band ends at 2: without the budget the bars must be outside it (the test can fail)
    assert rms(z_without) > 2.0, rms(z_without)


def test_model_error_factor_is_the_second_moment():
    """E E^T = (1/K) sum d_k d_k^T (not centred: a form error common to every mount is a bias too)."""
    d = np.array([[1.0, 2.0, 0.0], [3.0, -1.0, 1.0]])
    E = model_error_factor(d)
    # exact small-integer arithmetic up to rounding
    np.testing.assert_allclose(E @ E.T, (np.outer(d[0], d[0]) + np.outer(d[1], d[1])) / 2.0, rtol=1e-12)
    with pytest.raises(ValueError):
        model_error_factor(np.array([[np.nan, 1.0]]))


def _sensitive_problem(module):
    """The same pure data as above scaled to a noise-free measurement of a sensitive model: noise
    1e-12 rad and a process of 4e-9 rad, with five sources whose prior spreads move the data by
    ~1e-3 rad (G's columns ~1e9 noise units, as the consistent model's on a noise-free fit) and
    whose estimates sit a prior spread from its mean (z = J (x - mean) - r ~1e-3 rad)."""
    rng = np.random.default_rng(11)
    c = rng.uniform(-1.0, 1.0, size=(80, 2))
    y = np.linalg.cholesky(discrepancy_covariance(c, 1e-12, np.full(3, 4e-9), 0.7)) @ rng.normal(size=240)
    J = 1e-3 * rng.normal(size=(240, 5))
    x = 0.5 + 0.3 * rng.choice([-1.0, 1.0], size=5)
    return module.fit_discrepancy(-y, J, x, np.full(5, 0.5), np.full(5, 0.3), c, polynomial=False)


def test_fit_discrepancy_finds_a_small_process_beside_sensitive_sources():
    """The marginal likelihood's low-rank form must not cancel: with G's columns 1e9 noise units
    the Woodbury difference w'w - u'u (before session 18) jittered by ~1e-4 between steps of
    1e-8 in a log-parameter, L-BFGS-B's difference gradient was noise and the fit stopped where
    it started (the noise at half the residual RMS, the amplitudes at the RMS, the length at
    0.5). Now the amplitude is found within the factor 3 of the test above (same draw, scaled)
    and the noise far below it."""
    import flexcal.calibration.discrepancy as module

    found = _sensitive_problem(module)
    assert np.all((found.amplitude > 4e-9 / 3.0) & (found.amplitude < 4e-9 * 3.0)), found.amplitude  # factor 3: above
    assert found.noise < 4e-10  # a tenth of the process: the data hold no white part above 1e-12 (floor: NOISE_FLOOR x the residual RMS)



def test_noise_free_discrepancy_fit_does_not_hang_on_round_off():
    """The inputs of the discrepancy fit of the README's noise-free main job (flexcal verify
    --scenario table1 at d6128f6, the consistent model's estimate: residual 0.0018 urad RMS,
    231 rows, 45 sources; tests/data/noise_free_discrepancy_inputs.npz), moved by 1e-9
    relative: the fitted hyperparameters must not jump. With the estimated noise allowed down to
    1e-3 of the residual (before session 26) they did: log-likelihood 5340-5445, the Matern
    amplitudes and tau a factor 10-40 apart, the base-parameter z RMS 0.07-2.27 between such
    runs. With ``NOISE_FLOOR`` the spread is <= 1 % (measured 1.0 % on one amplitude, 3.5 % on
    tau, 1e-3 in the log-likelihood)."""
    from pathlib import Path

    a = dict(np.load(Path(__file__).parent / "data" / "noise_free_discrepancy_inputs.npz"))
    rng = np.random.default_rng(0)
    fits = []
    for k in range(3):
        moved = 1.0 + 1e-9 * k * rng.normal(size=a["x"].shape)
        found = fit_discrepancy(a["residual"], a["jacobian"], a["x"] * moved, a["prior_mean"], a["prior_std"],
                                a["coordinates"])
        fits.append([*found.amplitude, found.noise, found.length, found.log_likelihood])
    fits = np.array(fits)
    spread = (fits.max(0) - fits.min(0)) / np.abs(fits).mean(0)
    # 5 %: five times the largest spread measured with the floor (1 %); without it 0.5-40x
    assert np.all(spread[:5] < 0.05), spread
    # the log-likelihood (~4844) within 0.1: with the floor 1e-3 apart, without it up to 105
    assert fits[:, 5].max() - fits[:, 5].min() < 0.1, fits[:, 5]
