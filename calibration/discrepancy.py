"""Model discrepancy in the error bars (Kennedy-O'Hagan in spirit): a Gaussian process over the
postures, estimated from the fit residual, and the sandwich covariance of the estimate.

A real mount is never exactly the model: the data are ``y = f(x_true) + delta + eps`` with eps
the sensor noise (white, sigma^2 per channel) and delta the model's form error, a smooth
function of the posture. The least-squares/MAP estimate absorbs the part of delta its Jacobian
can mimic, and that part is a bias the noise-only error bars do not carry (z-scores of 8-16 on
FEM truth); an AR(1) inflation of the noise widens every bar by one factor instead, too much
for the sources delta does not look like (z RMS 0.1-0.5 on the ``paper`` mount). Here:

- **discrepancy model**: per angle a, delta_a is a zero-mean Gaussian process over the
  posture coordinates c (the measured angles divided by the workspace half-widths: 1 = the
  workspace edge), the sum of two independent parts: a Matern-5/2 process, variance s_a^2
  [rad^2] and one length scale l [workspace units], and a quadratic polynomial
  ``phi(c)^T beta_a`` (features 1, c_i, c_i^2 and c_i c_j, i < j; ``polynomial_features``)
  with coefficients beta_a ~ N(0, tau^2 I), one tau [rad] for the three angles; independent
  between angles and of the noise. The polynomial part is what a stationary kernel cannot
  give: a form error that is mostly gain (linear in the posture) and little offset, as the
  missing second-order terms of a model are (docs/calibration.md 6, "Why the imperfect-model
  test fails"); a Matern process of any length scale gives an offset mode and a gain mode
  comparable variance, so its bars are either too narrow for the gain-like combinations or
  too wide for the rest (measured, docs/calibration.md 6, 2026-11-27: the polynomial part takes
  table1's base parameters on FEM truth from z RMS 9.2 to 2.6, not yet into [0.5, 2]);
- **estimated from the measurement, the model and its Jacobian only** (no truth): the
  hyperparameters (sigma unless given, s_x, s_y, s_z, l, tau) maximize the marginal likelihood of
  the linearized data ``z = J (x_hat - mean) - r ~ N(0, J D J^T + sigma^2 I + K)`` (K the Matern
  and polynomial parts; r = model -
  data at the estimate, D the prior covariance): the prior's J D J^T term lets the parameters
  take whatever part of z they can explain (restricted maximum likelihood, with the prior in
  place of flat fixed effects), so the discrepancy is sized by what the parameters *cannot*
  fit and its smoothness, and the part of delta the parameters can mimic is assumed as large
  as a draw of the same process would put there; the polynomial part enters the likelihood
  like extra parameters with prior std tau (a low-rank term, Woodbury), so tau is sized by how
  far the sources' estimates and the residual together go beyond what the prior and the
  Matern part explain along the polynomial's directions;
- **sandwich covariance**: the estimate keeps its own weighting (rows / sigma_w, prior
  precision P); its error e = A (J^T (delta + eps) / sigma_w^2 + P (mean - x_true)),
  A = (J^T J / sigma_w^2 + P)^+, has ``Cov = A (J^T Sigma J / sigma_w^4 + P) A`` with
  ``Sigma = sigma^2 I + K`` (equal to A when Sigma = sigma_w^2 I: white noise gives back the
  Gauss-Newton bars). Every source's standard error and every base parameter's (c^T Cov c)
  come from this one matrix;
- **model-error budget** (issue 28, session 16): a form error the sources absorb whole leaves
  no trace in the residual, so nothing fitted from it can carry it. When the caller has
  samples of the model's error on these postures (prototype - model at the estimate,
  computed outside the calibration model: ``validation.runs.error_budget``),
  their second moment E E^T (``model_error_factor``) is added to Sigma in the sandwich.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

__all__ = ["Discrepancy", "fit_discrepancy", "discrepancy_covariance", "sandwich_covariance", "matern52",
           "polynomial_features", "model_error_factor"]

# The estimated white noise is at least this fraction of the residual's RMS (was 1e-3 until
# session 26). On a noise-free measurement the noise went to that old floor, Sigma = sigma^2 I +
# the Matern part became near singular, and the likelihood turned rugged: on the README's main
# job, inputs moved by 1e-9 relative gave log-likelihoods 5340-5445 at hyperparameters a factor
# 10-40 apart, and the base-parameter z RMS went 0.07-2.27 with where L-BFGS-B stopped. At 0.1
# the same perturbations move the fit by <= 1.4 % and the log-likelihood by 1e-3. On all 30
# noisy fits of the z-score study (0.5 urad) the noise came out at 0.971-1.057 x the residual
# and the fit is the same to the bit (docs/calibration.md, "Session 26").
NOISE_FLOOR = 0.1
LENGTH_BOUNDS = (0.03, 10.0)  # [workspace units] 3 % of a half-width (shorter is indistinguishable from
# noise at 77 postures: neighbours are ~0.1 apart) to 10 (longer is a constant, which the offsets absorb)


def polynomial_features(coordinates: np.ndarray) -> np.ndarray:
    """(n, p) features of the quadratic discrepancy at postures ``coordinates`` (n, k)
    [workspace units]: 1, c_i, c_i^2, then c_i c_j for i < j; p = 1 + 2k + k(k-1)/2 (10 for
    the three angles)."""
    c = np.asarray(coordinates, float)
    n, k = c.shape
    cross = [c[:, i] * c[:, j] for i in range(k) for j in range(i + 1, k)]
    return np.column_stack([np.ones(n), c, c * c, *cross]) if k else np.ones((n, 1))


def _polynomial_factor(features: np.ndarray, tau: float) -> np.ndarray:
    """(3n, 3p) F with F F^T the polynomial part's covariance [rad^2], points major: one
    coefficient vector per angle, each N(0, tau^2 I)."""
    return tau * np.kron(features, np.eye(3))


def _matern_noise_covariance(distance: np.ndarray, noise: float, amplitude: np.ndarray, length: float) -> np.ndarray:
    """(3n, 3n) [rad^2] sigma^2 I + the Matern part over postures at ``distance`` (n, n), points major."""
    K = np.kron(matern52(distance, length), np.diag(np.asarray(amplitude, float) ** 2))
    return K + noise ** 2 * np.eye(K.shape[0])


def matern52(distance: np.ndarray, length: float) -> np.ndarray:
    """Matern-5/2 correlation of distances [workspace units] at length scale ``length``."""
    a = math.sqrt(5.0) * np.asarray(distance, float) / length
    return (1.0 + a + a * a / 3.0) * np.exp(-a)


@dataclass(frozen=True, kw_only=True)
class Discrepancy:
    """noise sigma [rad] (white, every channel) and whether it was given; amplitude (3,) [rad]
    the Matern part's standard deviation per angle; length [workspace units]; polynomial: tau
    [rad], the std of each coefficient of the quadratic part (None: no polynomial part);
    log_likelihood at the optimum; coordinates (n, k) the posture coordinates it lives on;
    model_error (3n, K) [rad]: the factor E of the model-error budget (``model_error_factor``),
    E E^T its covariance, or None (no budget given)."""

    noise: float
    noise_given: bool
    amplitude: np.ndarray
    length: float
    polynomial: float | None
    log_likelihood: float
    coordinates: np.ndarray
    model_error: np.ndarray | None = None

    @property
    def covariance(self) -> np.ndarray:
        """Sigma (3n, 3n) [rad^2] = sigma^2 I + K (+ the model-error budget E E^T), points major."""
        S = discrepancy_covariance(self.coordinates, self.noise, self.amplitude, self.length, self.polynomial)
        return S if self.model_error is None else S + self.model_error @ self.model_error.T

    def as_dict(self) -> dict:
        return {"noise_urad": self.noise * 1e6, "noise_given": self.noise_given,
                "amplitude_urad": (self.amplitude * 1e6).tolist(), "length_scale_workspace": self.length,
                "polynomial_tau_urad": None if self.polynomial is None else self.polynomial * 1e6,
                "kernel": "Matern 5/2 over the measured angles / workspace half-widths, one process per angle"
                          + ("" if self.polynomial is None else
                             " + a quadratic polynomial per angle (features 1, c_i, c_i^2, c_i c_j; each "
                             "coefficient N(0, tau^2))"),
                "log_likelihood": self.log_likelihood,
                "model_error_budget": None if self.model_error is None else {
                    "n_samples": int(self.model_error.shape[1]),
                    "rms_urad": float(np.sqrt(np.sum(self.model_error ** 2) / self.model_error.shape[0]) * 1e6),
                    "what": "second moment of the given samples of the model's error on the measured postures "
                            "(prototype - model), in the sandwich next to the fitted discrepancy"}}


def discrepancy_covariance(coordinates: np.ndarray, noise: float, amplitude: np.ndarray, length: float,
                           polynomial: float | None = None) -> np.ndarray:
    """(3n, 3n) [rad^2] sigma^2 I + K over postures ``coordinates`` (n, k), points major: the
    Matern part (amplitude (3,) [rad], length [workspace units]) plus, with ``polynomial`` tau
    [rad], the quadratic part ``F F^T``."""
    c = np.asarray(coordinates, float)
    distance = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=-1)
    S = _matern_noise_covariance(distance, noise, amplitude, length)
    if polynomial is not None:
        F = _polynomial_factor(polynomial_features(c), polynomial)
        S = S + F @ F.T
    return S


def _unpack(theta: np.ndarray, noise: float | None, polynomial: bool) -> tuple[float, np.ndarray, float, float | None]:
    """(sigma, amplitude (3,), length, tau or None) from the optimizer's log-parameters
    [log sigma unless noise is given, log s_x, log s_y, log s_z, log l, log tau if polynomial]."""
    head = 0 if noise is not None else 1
    sigma = float(noise) if noise is not None else math.exp(theta[0])
    tau = math.exp(theta[head + 4]) if polynomial else None
    return sigma, np.exp(theta[head:head + 3]), math.exp(theta[head + 3]), tau


def _negative_log_likelihood(theta: np.ndarray, z: np.ndarray, G: np.ndarray, distance: np.ndarray,
                             noise: float | None, keep: np.ndarray | None, features: np.ndarray | None) -> float:
    """-log N(z; 0, G G^T + F F^T + Sigma) up to a constant, Sigma = sigma^2 I + the Matern
    part, F the polynomial part's factor (all projected by keep), with [G, F] =: G' as a
    low-rank factor: with L L^T = Sigma, w = L^-1 z and V = L^-1 G',

        z^T (G' G'^T + Sigma)^-1 z = min_a |w - V a|^2 + |a|^2,
        log det (G' G'^T + Sigma) = 2 log det L + log det (I + V^T V),

    both from one QR factorization of [V; I] (R^T R = I + V^T V), the minimum's residual
    computed as it is, never as w^T w - u^T u. That difference (the Woodbury form used before
    session 18) cancels catastrophically when a source is sensitive and the noise small (V's
    columns 10^6 and more on a noise-free measurement): measured on the consistent model's
    noise-free table1 fit, the value jittered by ~1e-4 between steps of 1e-8 in a
    log-parameter, L-BFGS-B's difference gradient was noise and the fit stopped at its start
    (the bars 18x too narrow, base z RMS 5.1); with the QR the steps change it smoothly
    (1.5e-6 per 1e-8). Sigma is well conditioned (sigma^2 on its diagonal), so a sensitive
    source does not break its Cholesky factor."""
    from scipy.linalg import solve_triangular

    sigma, amplitude, length, tau = _unpack(theta, noise, features is not None)
    if tau is not None:
        F = _polynomial_factor(features, tau)
        G = np.concatenate([G, F if keep is None else keep.T @ F], axis=1)
    try:
        w, V, log_det_L = _whiten(z, G, distance, sigma, amplitude, length, keep)
    except np.linalg.LinAlgError:
        return 1e300
    k = V.shape[1]
    Q, R = np.linalg.qr(np.vstack([V, np.eye(k)]))
    a = solve_triangular(R, Q[:len(w)].T @ w)  # the minimizer of |w - V a|^2 + |a|^2
    misfit = w - V @ a
    quadratic = misfit @ misfit + a @ a
    return float(0.5 * quadratic + log_det_L + np.sum(np.log(np.abs(np.diag(R)))))


def _whiten(z: np.ndarray, G: np.ndarray, distance: np.ndarray, noise: float, amplitude: np.ndarray,
            length: float, keep: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, float]:
    """w = L^-1 z, V = L^-1 G and log det L, for L L^T = Sigma = sigma^2 I + the Matern part
    over postures at ``distance`` (n, n) (amplitude (3,) [rad], length [workspace units], points
    major), projected by keep if given. Without keep Sigma is block diagonal by angle (the
    angles' processes and the noise are independent): the rows a::3 hold s_a^2 M + sigma^2 I,
    so three n x n Cholesky factors and triangular solves replace one 3n x 3n factor and two
    general solves (a fit 4-8x faster, docs/testing.md). The rows of w and V come out angle
    major; |w - V a|^2 and the QR of [V; I] do not depend on the order of the rows."""
    from scipy.linalg import solve_triangular

    if keep is not None:
        L = np.linalg.cholesky(keep.T @ _matern_noise_covariance(distance, noise, amplitude, length) @ keep)
        wV = solve_triangular(L, np.column_stack([z, G]), lower=True)
        return wV[:, 0], wV[:, 1:], float(np.sum(np.log(np.diag(L))))
    correlation = matern52(distance, length)
    blocks, log_det_L = [], 0.0
    noise_diagonal = noise ** 2 * np.eye(correlation.shape[0])
    for angle in range(3):
        L = np.linalg.cholesky(amplitude[angle] ** 2 * correlation + noise_diagonal)
        blocks.append(solve_triangular(L, np.column_stack([z[angle::3], G[angle::3]]), lower=True))
        log_det_L += float(np.sum(np.log(np.diag(L))))
    wV = np.concatenate(blocks)
    return wV[:, 0], wV[:, 1:], log_det_L


def model_error_factor(samples: np.ndarray) -> np.ndarray:
    """(m, K) [rad] factor E of the model-error budget from K samples (K, m) [rad] of
    "prototype - model" on the measured trajectory (points major, 3 angles a point): E E^T =
    the samples' second moment (1/K) sum d_k d_k^T, not their centred covariance: the error the
    model makes everywhere (its form error at the nominal mount) is a bias of the estimate as
    much as the part that changes between mounts."""
    d = np.atleast_2d(np.asarray(samples, float))
    if d.ndim != 2 or not np.all(np.isfinite(d)):
        raise ValueError(f"model-error samples must be a finite (K, m) array, got shape {d.shape}")
    return d.T / math.sqrt(d.shape[0])


def fit_discrepancy(residual: np.ndarray, jacobian: np.ndarray, x: np.ndarray, prior_mean: np.ndarray,
                    prior_std: np.ndarray, coordinates: np.ndarray, *, noise: float | None = None,
                    polynomial: bool = True, model_error: np.ndarray | None = None) -> Discrepancy:
    """Noise and discrepancy by maximum marginal likelihood (module doc).

    residual (3n,) [rad] model - data at the estimate x (d,) [unit box]; jacobian (3n, d) [rad per
    unit box]; prior_mean, prior_std (d,) [unit box] (std inf: no prior; such a direction is
    projected out of z instead, the restricted likelihood proper); coordinates (n, k) posture
    coordinates [workspace units]; noise: the sensor noise [rad] if known, else estimated;
    polynomial: with the quadratic part (False: the Matern part alone, as before issue 28's
    item 1 was built; kept to measure against); model_error (K, 3n) [rad]: samples of the
    model's error on these postures (prototype - model, ``model_error_factor``), a known
    covariance E E^T added to Sigma after the fit; None: none known. It is not put into the
    likelihood: there it "explains" part of z and the fitted parts shrink (measured on the
    analytic prototype, 2026-11-28: some bars then narrowed, z 2.1 -> 4.1), while the sandwich
    sees mostly the part of E the sources absorb and the fitted parts mostly the rest, so the
    sum double-counts little and a bar never narrows.
    """
    r = np.asarray(residual, float)
    J = np.asarray(jacobian, float)
    c = np.asarray(coordinates, float)
    if r.size != 3 * c.shape[0] or J.shape[0] != r.size:
        raise ValueError(f"residual ({r.size}), jacobian ({J.shape[0]} rows) and 3 x {c.shape[0]} postures disagree")
    finite = np.isfinite(prior_std)
    offset = np.where(finite, np.asarray(x, float) - prior_mean, 0.0)
    z = J @ offset - r
    G = J[:, finite] * prior_std[finite]  # the prior's part: J D J^T = G G^T
    E = None
    if model_error is not None:  # added to Sigma after the fit, not to the likelihood (docstring)
        E = model_error_factor(model_error)
        if E.shape[0] != r.size:
            raise ValueError(f"model-error samples have {E.shape[0]} rows, the residual {r.size}")
    keep = None
    if not np.all(finite):  # free directions: project them out (restricted likelihood)
        from scipy.linalg import null_space

        keep = null_space(J[:, ~finite].T)  # (m, m - rank): directions no free source reaches
        z, G = keep.T @ z, keep.T @ G
    distance = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=-1)
    scale = max(float(np.sqrt(np.mean(r ** 2))), 1e-12)
    features = polynomial_features(c) if polynomial else None
    # one BLAS thread: the likelihood works on (3n, 3n) matrices of a few hundred rows, where a
    # multi-threaded BLAS on a shared 2-core machine was measured 5-150x slower (session 15-16)
    with threadpool_limits(1, user_api="blas"):
        best = _maximize_likelihood(z, G, distance, noise, keep, features, scale, polynomial)
    sigma, amplitude, length, tau = _unpack(best.x, noise, polynomial)
    return Discrepancy(noise=sigma, noise_given=noise is not None, amplitude=amplitude, length=length,
                       polynomial=tau, log_likelihood=-float(best.fun), coordinates=c, model_error=E)


def _maximize_likelihood(z, G, distance, noise, keep, features, scale, polynomial):
    """The L-BFGS-B optimum of the marginal likelihood over a few starting length scales."""
    from scipy.optimize import minimize

    lo, hi = math.log(LENGTH_BOUNDS[0]), math.log(LENGTH_BOUNDS[1])
    amplitude_bounds = (math.log(scale * 1e-3), math.log(scale * 1e2))
    best = None
    for start_length in (0.1, 0.5, 2.0):  # a few starts: the likelihood can have a short and a long mode
        theta0 = [math.log(scale)] * 3 + [math.log(start_length)]
        bounds = [amplitude_bounds] * 3 + [(lo, hi)]
        if noise is None:
            theta0 = [math.log(scale / 2.0)] + theta0
            bounds = [(math.log(scale * NOISE_FLOOR), math.log(scale * 10.0))] + bounds
        if polynomial:  # tau: a coefficient of the order of the residual, bounded like the amplitudes
            theta0, bounds = theta0 + [math.log(scale)], bounds + [amplitude_bounds]
        found = minimize(_negative_log_likelihood, np.array(theta0), args=(z, G, distance, noise, keep, features),
                         method="L-BFGS-B", bounds=bounds)
        if best is None or found.fun < best.fun:
            best = found
    return best


def sandwich_covariance(posterior_covariance: np.ndarray, J: np.ndarray, weight_noise: float,
                        prior_precision: np.ndarray, data_covariance: np.ndarray) -> np.ndarray:
    """Cov (d, d) [unit box^2] of the estimate weighted by rows / weight_noise [rad] and prior
    precision (d,) [1/unit box^2], when the data's error has covariance data_covariance (m, m)
    [rad^2]: A (J^T Sigma J / sigma_w^4 + P) A with A = posterior_covariance (d, d), the
    estimator's own (J^T J / sigma_w^2 + P)^+ (``estimation.posterior``)."""
    A = np.asarray(posterior_covariance, float)
    Jw = np.asarray(J, float) / weight_noise ** 2
    middle = Jw.T @ data_covariance @ Jw + np.diag(prior_precision)
    cov = A @ middle @ A
    return 0.5 * (cov + cov.T)
