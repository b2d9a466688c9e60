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
  workspace edge) with a Matern-5/2 kernel, variance s_a^2 [rad^2] and one length scale l
  [workspace units]; independent between angles and of the noise;
- **estimated from the measurement, the model and its Jacobian only** (no truth): the
  hyperparameters (sigma unless given, s_x, s_y, s_z, l) maximize the marginal likelihood of
  the linearized data ``z = J (x_hat - mean) - r ~ N(0, J D J^T + sigma^2 I + K)`` (r = model -
  data at the estimate, D the prior covariance): the prior's J D J^T term lets the parameters
  take whatever part of z they can explain (restricted maximum likelihood, with the prior in
  place of flat fixed effects), so the discrepancy is sized by what the parameters *cannot*
  fit and its smoothness, and the part of delta the parameters can mimic is assumed as large
  as a draw of the same process would put there;
- **sandwich covariance**: the estimate keeps its own weighting (rows / sigma_w, prior
  precision P); its error e = A (J^T (delta + eps) / sigma_w^2 + P (mean - x_true)),
  A = (J^T J / sigma_w^2 + P)^+, has ``Cov = A (J^T Sigma J / sigma_w^4 + P) A`` with
  ``Sigma = sigma^2 I + K`` (equal to A when Sigma = sigma_w^2 I: white noise gives back the
  Gauss-Newton bars). Every source's standard error and every base parameter's (c^T Cov c)
  come from this one matrix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Discrepancy", "fit_discrepancy", "discrepancy_covariance", "sandwich_covariance", "matern52"]

LENGTH_BOUNDS = (0.03, 10.0)  # [workspace units] 3 % of a half-width (shorter is indistinguishable from
# noise at 77 postures: neighbours are ~0.1 apart) to 10 (longer is a constant, which the offsets absorb)


def matern52(distance: np.ndarray, length: float) -> np.ndarray:
    """Matern-5/2 correlation of distances [workspace units] at length scale ``length``."""
    a = math.sqrt(5.0) * np.asarray(distance, float) / length
    return (1.0 + a + a * a / 3.0) * np.exp(-a)


@dataclass(frozen=True, kw_only=True)
class Discrepancy:
    """noise sigma [rad] (white, every channel) and whether it was given; amplitude (3,) [rad]
    the discrepancy's standard deviation per angle; length [workspace units]; log_likelihood
    at the optimum; coordinates (n, k) the posture coordinates it lives on."""

    noise: float
    noise_given: bool
    amplitude: np.ndarray
    length: float
    log_likelihood: float
    coordinates: np.ndarray

    @property
    def covariance(self) -> np.ndarray:
        """Sigma (3n, 3n) [rad^2] = sigma^2 I + K, points major."""
        return discrepancy_covariance(self.coordinates, self.noise, self.amplitude, self.length)

    def as_dict(self) -> dict:
        return {"noise_urad": self.noise * 1e6, "noise_given": self.noise_given,
                "amplitude_urad": (self.amplitude * 1e6).tolist(), "length_scale_workspace": self.length,
                "kernel": "Matern 5/2 over the measured angles / workspace half-widths, one process per angle",
                "log_likelihood": self.log_likelihood}


def discrepancy_covariance(coordinates: np.ndarray, noise: float, amplitude: np.ndarray, length: float) -> np.ndarray:
    """(3n, 3n) [rad^2] sigma^2 I + K over postures ``coordinates`` (n, k), points major."""
    c = np.asarray(coordinates, float)
    distance = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=-1)
    K = np.kron(matern52(distance, length), np.diag(np.asarray(amplitude, float) ** 2))
    return K + noise ** 2 * np.eye(K.shape[0])


def _negative_log_likelihood(theta: np.ndarray, z: np.ndarray, G: np.ndarray, distance: np.ndarray,
                             noise: float | None, keep: np.ndarray | None) -> float:
    """-log N(z; 0, G G^T + Sigma) up to a constant, Sigma = sigma^2 I + K (projected by keep),
    by the Woodbury identity and the determinant lemma: Sigma is well conditioned (sigma^2 on
    its diagonal), I + G^T Sigma^-1 G has eigenvalues >= 1, so a sensitive source (G's columns
    10^4 noise units and more on a designed trajectory) does not break the factorization."""
    if noise is None:
        sigma, amplitude, length = math.exp(theta[0]), np.exp(theta[1:4]), math.exp(theta[4])
    else:
        sigma, amplitude, length = noise, np.exp(theta[0:3]), math.exp(theta[3])
    S = np.kron(matern52(distance, length), np.diag(amplitude ** 2)) + sigma ** 2 * np.eye(distance.shape[0] * 3)
    if keep is not None:
        S = keep.T @ S @ keep
    try:
        L = np.linalg.cholesky(S)
        w, V = np.linalg.solve(L, z), np.linalg.solve(L, G)
        inner = np.eye(G.shape[1]) + V.T @ V
        M = np.linalg.cholesky(inner)
    except np.linalg.LinAlgError:
        return 1e300
    u = np.linalg.solve(M, V.T @ w)
    return float(0.5 * (w @ w - u @ u) + np.sum(np.log(np.diag(L))) + np.sum(np.log(np.diag(M))))


def fit_discrepancy(residual: np.ndarray, jacobian: np.ndarray, x: np.ndarray, prior_mean: np.ndarray,
                    prior_std: np.ndarray, coordinates: np.ndarray, *, noise: float | None = None) -> Discrepancy:
    """Noise and discrepancy by maximum marginal likelihood (module doc).

    residual (3n,) [rad] model - data at the estimate x (d,) [unit box]; jacobian (3n, d) [rad per
    unit box]; prior_mean, prior_std (d,) [unit box] (std inf: no prior; such a direction is
    projected out of z instead, the restricted likelihood proper); coordinates (n, k) posture
    coordinates [workspace units]; noise: the sensor noise [rad] if known, else estimated.
    """
    from scipy.optimize import minimize

    r = np.asarray(residual, float)
    J = np.asarray(jacobian, float)
    c = np.asarray(coordinates, float)
    if r.size != 3 * c.shape[0] or J.shape[0] != r.size:
        raise ValueError(f"residual ({r.size}), jacobian ({J.shape[0]} rows) and 3 x {c.shape[0]} postures disagree")
    finite = np.isfinite(prior_std)
    offset = np.where(finite, np.asarray(x, float) - prior_mean, 0.0)
    z = J @ offset - r
    G = J[:, finite] * prior_std[finite]  # the prior's part: J D J^T = G G^T
    keep = None
    if not np.all(finite):  # free directions: project them out (restricted likelihood)
        from scipy.linalg import null_space

        keep = null_space(J[:, ~finite].T)  # (m, m - rank): directions no free source reaches
        z, G = keep.T @ z, keep.T @ G
    distance = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=-1)
    scale = max(float(np.sqrt(np.mean(r ** 2))), 1e-12)
    lo, hi = math.log(LENGTH_BOUNDS[0]), math.log(LENGTH_BOUNDS[1])
    amplitude_bounds = (math.log(scale * 1e-3), math.log(scale * 1e2))
    best = None
    for start_length in (0.1, 0.5, 2.0):  # a few starts: the likelihood can have a short and a long mode
        theta0 = [math.log(scale)] * 3 + [math.log(start_length)]
        bounds = [amplitude_bounds] * 3 + [(lo, hi)]
        if noise is None:
            theta0 = [math.log(scale / 2.0)] + theta0
            bounds = [(math.log(scale * 1e-3), math.log(scale * 10.0))] + bounds
        found = minimize(_negative_log_likelihood, np.array(theta0), args=(z, G, distance, noise, keep),
                         method="L-BFGS-B", bounds=bounds)
        if best is None or found.fun < best.fun:
            best = found
    theta = best.x
    if noise is None:
        sigma, amplitude, length = math.exp(theta[0]), np.exp(theta[1:4]), math.exp(theta[4])
    else:
        sigma, amplitude, length = float(noise), np.exp(theta[0:3]), math.exp(theta[3])
    return Discrepancy(noise=sigma, noise_given=noise is not None, amplitude=amplitude, length=length,
                       log_likelihood=-float(best.fun), coordinates=c)


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
