"""Estimation of all error sources with priors (MAP), their standard errors and the prior scale.

The paper identifies a Sobol-screened subset with a PSO and leaves the rest at nominal.
Here every source is estimated at once, with the paper's ranges (Eq. 9) as a Gaussian
prior, so that the sources the data cannot see stay at their prior instead of wandering:

- coordinates are the unit box of Eq. 9 (``ParameterSpace.to_unit``); the prior of each
  source is the Gaussian with the moments of the uniform distribution over its range,
  mean 0.5 and standard deviation ``scale / sqrt(12)`` [fraction of the range], ``scale``
  chosen by cross-validation (``choose_prior_scale``); ``scale = inf`` is free least squares;
- the MAP estimate minimizes ``||r(x)/sigma||^2 + ||(x - mean)/std||^2`` inside the box
  (``scipy.optimize.least_squares``, trf, batched finite-difference Jacobians:
  ``calibration.polish.least_squares_polish``);
- the noise ``sigma`` [rad] is either given (sensor specification) or estimated from the
  residual, ``sigma^2 = RSS / (m - p_eff)`` with ``p_eff = trace(H)`` the effective number of
  parameters of the linearized MAP (the hat matrix ``H = J Sigma J^T / sigma^2``), refitted
  until it settles; with a model-form error the estimate includes it, which is the honest
  error bar for a model that cannot fit the truth exactly;
- a model-form error is not white: it is smooth along the trajectory, so neighbouring
  residuals are correlated and the data hold fewer independent observations than rows. The
  lag-1 autocorrelation rho of the residuals along the point order (pooled over the angles)
  inflates the noise variance by the AR(1) factor (1 + rho) / (1 - rho) (the effective sample
  size n (1 - rho) / (1 + rho)); white noise gives rho ~ 0 and no inflation. It enters the
  fit's weighting too, so correlated misfit pulls less against the prior;
- the Gauss-Newton covariance at the solution, ``Sigma = (J^T J / sigma^2 + diag(1/std^2))^-1``
  [unit box^2], gives every source's standard error (times its range for SI) when the misfit
  is white. With posture ``coordinates`` (the pipeline passes them) the error bars carry the
  model's discrepancy instead (``calibration.discrepancy``): a Gaussian process over the
  postures plus white noise, sized by maximum marginal likelihood from the residual, and the
  sandwich covariance of the estimate under it; the AR(1)-inflated sigma then only weighs the
  data against the prior in the fit. At an active bound the covariance is the unconstrained
  one: a standard error then overstates what the bound already pins down (``at_bound``).

The prior scale is chosen by K-fold cross-validation over held-out *whole legs* (contiguous
blocks of the trajectory): random held-out points leak time-correlated information (docs/
calibration.md). Each fold fits from the prior mean, never from the full-data solution.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from flexcal.calibration.discrepancy import Discrepancy, fit_discrepancy, sandwich_covariance
from flexcal.calibration.polish import BUDGET_STATUS, batched_jacobian_fd, least_squares_polish

__all__ = ["Prior", "uniform_prior", "Estimate", "estimate", "map_objective_rows", "fit_evaluations", "with_model_error", "with_discrepancy_bars", "posterior", "residual_autocorrelation", "choose_prior_scale", "CrossValidation",
           "held_out_folds", "PRIOR_SCALES", "one_standard_error_choice"]

Residuals = Callable[[np.ndarray], np.ndarray]
GIVEN = "given"  # Estimate.noise_source of a given noise
UNIFORM_STD = 1.0 / math.sqrt(12.0)  # [fraction of range] standard deviation of a uniform distribution
PRIOR_SCALES = (1.0, 2.0, 4.0)  # cross-validation grid [x the range's own spread]. Never below 1: the
# paper's ranges (Eq. 9) are what is known; a narrower prior claims more and, when the sources
# really spread over their ranges, biases the identified ones (measured: a cross-validated 0.3 gave
# z-score RMS 2.7-3.1 where 1 gave 1.1-1.2, table1 seed 1). Free least squares is its own method.
FD_STEP = 1e-6  # [unit box] forward-difference step: 1e-6 of a range is far above the model's fixed-point
# tolerance (1e-13 m on mm-scale positions) and far below any curvature scale of the model


@dataclass(frozen=True, kw_only=True)
class Prior:
    """Gaussian prior on the unit box: mean (d,) and std (d,) [fraction of range]; std = inf
    for a source without prior (free)."""

    mean: np.ndarray
    std: np.ndarray

    def __post_init__(self) -> None:
        mean, std = np.asarray(self.mean, float), np.asarray(self.std, float)
        if mean.shape != std.shape or mean.ndim != 1:
            raise ValueError(f"prior mean and std must be equal 1-D shapes, got {mean.shape} and {std.shape}")
        if np.any(~(std > 0)):
            raise ValueError("prior standard deviations must be > 0 (inf for no prior)")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "std", std)

    @property
    def precision(self) -> np.ndarray:
        """(d,) 1/std^2 (0 where there is no prior)."""
        return 1.0 / self.std ** 2

    @property
    def is_free(self) -> bool:
        return bool(np.all(np.isinf(self.std)))


def uniform_prior(n_params: int, scale: float = 1.0) -> Prior:
    """The paper's ranges as a Gaussian prior: mean 0.5, std ``scale / sqrt(12)`` [fraction of
    range] (the moments of a uniform draw over the range, Eq. 9); ``scale = inf``: no prior."""
    if not scale > 0:
        raise ValueError(f"prior scale={scale} must be > 0 (inf for free least squares)")
    return Prior(mean=np.full(n_params, 0.5), std=np.full(n_params, scale * UNIFORM_STD))


@dataclass(frozen=True, kw_only=True)
class Estimate:
    """x (d,) [unit box] the estimate; std (d,) [fraction of range] standard errors;
    covariance (d, d) [unit box^2]; noise [residual units] sigma used, noise_source ("given"
    or "estimated from the residual (RSS / (m - p_eff))"); autocorrelation rho of the residual
    along the points and inflation (1 + rho)/(1 - rho) applied to the estimated noise variance
    (1 when the noise is given); n_observations m; p_eff effective
    number of parameters; residual (m,) at x; jacobian (m, d) of the residual at x (forward
    differences) [residual units per unit box]; rss; at_bound (d,) bool; n_evaluations
    (residual rows, Jacobians included); prior: the prior used; discrepancy: the model
    discrepancy the error bars carry (None: white misfit assumed, ``covariance`` is the
    Gauss-Newton one); gauss_newton_covariance (d, d): the white-misfit covariance at the same
    weighting, kept for comparison (None when it is ``covariance``); profile_bars: the
    profile-likelihood widening added to ``covariance`` (``calibration.profile_bars``), or None;
    stopped_at_budget: the last fit ended at its evaluation budget, not at a minimum (after
    ``estimate``'s ``budget_restarts``)."""

    x: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    noise: float
    noise_source: str
    autocorrelation: float
    inflation: float
    n_observations: int
    p_eff: float
    residual: np.ndarray
    jacobian: np.ndarray
    rss: float
    at_bound: np.ndarray
    n_evaluations: int
    prior: Prior
    discrepancy: Discrepancy | None = None
    gauss_newton_covariance: np.ndarray | None = None
    profile_bars: object | None = None  # calibration.profile_bars.ProfileBars (which imports this module)
    stopped_at_budget: bool = False

    @property
    def rms(self) -> float:
        return float(np.sqrt(self.rss / self.n_observations))


def posterior(J: np.ndarray, noise: float, prior: Prior) -> tuple[np.ndarray, float, np.ndarray]:
    """(Sigma (d, d) [unit box^2], p_eff, std (d,) [unit box]) of the linearized MAP, from one
    thin SVD of the whitened Jacobian stacked on the prior's square-root precision. J (m, d) the
    data Jacobian [residual units per unit box], noise sigma [residual units]. Sigma =
    (J^T J/sigma^2 + diag(prior precision))^+, a pseudo-inverse: finite, and right for every
    combination the data or the prior see (a base parameter's variance is c^T Sigma c); std =
    sqrt(diag Sigma), inf for a source that takes part in a direction neither the data nor a
    prior sees (free least squares on a rank-deficient problem); p_eff = trace(J Sigma
    J^T)/sigma^2.

    The SVD of the stacked matrix, not an eigendecomposition of the normal equations: the
    latter resolves an eigenvalue only to ~1e-16 of the largest, and a noise-free fit (its
    noise the model's, 0.003 urad on the consistent model's main job) puts the data's
    eigenvalues ~1e13 above the prior's, so a floor there declared prior-held directions
    unseen and their sources' bars infinite (session 21, docs/calibration.md 8)."""
    W = J / noise
    stacked = np.vstack([W, np.diag(np.sqrt(prior.precision))])
    _, singular, vt = np.linalg.svd(stacked, full_matrices=False)
    vectors = vt.T
    # below this a direction is numerically unseen: the SVD's round-off is ~1e-16 of the largest
    floor = max(singular.max(initial=0.0), 1e-300) * 1e-12
    seen = singular > floor
    sigma = (vectors[:, seen] / singular[seen] ** 2) @ vectors[:, seen].T
    p_eff = float(np.sum(np.sum((W @ vectors[:, seen]) ** 2, axis=0) / singular[seen] ** 2))
    unbounded = np.any(vectors[:, ~seen] ** 2 > 1e-12, axis=1)
    std = np.where(unbounded, np.inf, np.sqrt(np.maximum(np.diag(sigma), 0.0)))
    return sigma, p_eff, std


def residual_autocorrelation(r: np.ndarray, point_size: int = 3) -> float:
    """Lag-1 autocorrelation of a residual (m,) laid out points major (``point_size`` angles a
    point), pooled over the angles and clipped to [0, 0.95] (a negative one would shrink the
    error bars; 0.95 caps the inflation at 39x)."""
    r = np.asarray(r, float)
    if r.size % point_size:
        raise ValueError(f"residual length {r.size} is not a multiple of point_size={point_size}")
    R = r.reshape(-1, point_size)
    if R.shape[0] < 3:
        return 0.0
    R = R - R.mean(axis=0)
    denominator = float(np.sum(R ** 2))
    if denominator <= 0.0:
        return 0.0
    return float(np.clip(np.sum(R[1:] * R[:-1]) / denominator, 0.0, 0.95))


def map_objective_rows(residuals: Residuals, prior: Prior, sigma: float) -> Residuals:
    """X (n, d) -> (n, m + d_prior): the rows whose sum of squares is the MAP objective,
    ``||r(X) / sigma||^2 + ||(X - mean) / std||^2`` over the sources with a prior."""
    finite = np.isfinite(prior.std)
    weight = 1.0 / sigma  # multiplied, as the fits always did (the same bits)

    def rows(X: np.ndarray) -> np.ndarray:
        return np.concatenate([np.asarray(residuals(X), float) * weight,
                               (X[:, finite] - prior.mean[finite]) / prior.std[finite]], axis=1)
    return rows


def fit_evaluations(n_params: int) -> int:
    """A fit's budget of residual rows: 100 Jacobians' worth (module doc of ``estimate``)."""
    return 100 * (n_params + 2)


def estimate(residuals: Residuals, prior: Prior, *, noise: float | None = None, x0: np.ndarray | None = None,
             max_noise_rounds: int = 4, noise_rtol: float = 0.05, max_evaluations: int | None = None,
             point_size: int = 3, correlated: bool = True, coordinates: np.ndarray | None = None,
             model_error: np.ndarray | None = None, budget_restarts: int = 0) -> Estimate:
    """MAP (or free least squares when ``prior.is_free``) estimate on the unit box.

    residuals: ``r(X (n, d)) -> (n, m)`` [residual units, e.g. rad]; noise: sigma in those
    units, or None to estimate it from the residual (start: the fit with sigma equal to the
    prior-mean residual RMS / 10, then RSS/(m - p_eff), refitted until sigma changes by less
    than ``noise_rtol`` or ``max_noise_rounds`` fits; 5 % moves a standard error by 5 %,
    below what a z-score test can see); x0: start (default the prior mean); max_evaluations:
    residual rows per fit (None: 100 Jacobians' worth; free least squares on a rank-deficient
    problem creeps along its null space, give it more); point_size: residuals per point (the
    layout for the autocorrelation); correlated: inflate an estimated noise by the residual's
    AR(1) factor (module doc); coordinates (m / point_size, k) [workspace units]: the postures,
    for the model-discrepancy error bars (``calibration.discrepancy``; needs point_size 3 and a
    prior on every source, else ValueError); None: Gauss-Newton error bars; model_error (K, m)
    [residual units]: samples of the model's error on these rows (prototype - model at the
    nominal mount and prior draws: a model-error budget computed outside the calibration
    model, ``validation.runs.error_budget``), carried by the discrepancy error bars
    (``calibration.discrepancy.model_error_factor``); needs coordinates. budget_restarts: a fit
    that ends at its budget starts again from its best point with a fresh budget (and a fresh
    trust region), up to this many times; ``stopped_at_budget`` says whether the last one still
    did.
    """
    d = prior.mean.size
    x = np.clip(prior.mean if x0 is None else np.asarray(x0, float), 0.0, 1.0)
    r_start = np.asarray(residuals(x[None]), float)[0]
    m = r_start.size
    if m < 1:
        raise ValueError("no observations to estimate from")
    given = noise is not None
    if given and not noise > 0:
        raise ValueError(f"noise={noise} must be > 0")
    sigma = float(noise) if given else max(float(np.sqrt(np.mean(r_start ** 2))) / 10.0, 1e-12)
    n_evaluations = 1
    for _ in range(1 if given else max_noise_rounds):
        augmented = map_objective_rows(residuals, prior, sigma)
        # tolerances 1e-8 (relative change of the cost / of x): far below what the noise
        # resolves; the budget keeps a kinked residual (a clearance opening inside a step) from
        # making trf crawl: 100 Jacobians' worth of rows, where smooth fits take 10-40
        budget = max_evaluations if max_evaluations is not None else fit_evaluations(d)
        for _ in range(1 + max(int(budget_restarts), 0)):
            fit = least_squares_polish(augmented, x, fd_step=FD_STEP, ftol=1e-8, xtol=1e-8, gtol=1e-8,
                                       max_evaluations=budget)
            n_evaluations += fit.n_evaluations
            x = fit.x
            if fit.status != BUDGET_STATUS:
                break
        J, r = batched_jacobian_fd(residuals, x, step=FD_STEP)
        n_evaluations += d + 1
        rss = float(r @ r)
        _, p_eff, _ = posterior(J, sigma, prior)
        if given:
            break
        rho = residual_autocorrelation(r, point_size) if correlated else 0.0
        new = math.sqrt(rss / max(m - p_eff, 1.0) * (1.0 + rho) / (1.0 - rho))
        converged = abs(new - sigma) <= noise_rtol * sigma
        sigma = max(new, 1e-12)
        if converged:
            break
    sigma_matrix, p_eff, std = posterior(J, sigma, prior)
    rho = 0.0 if given or not correlated else residual_autocorrelation(r, point_size)
    at_bound = (x <= 1e-9) | (x >= 1.0 - 1e-9)
    if model_error is not None and coordinates is None:
        raise ValueError("a model-error budget enters the discrepancy error bars: give the postures' coordinates too")
    fitted = Estimate(x=x, std=std, covariance=sigma_matrix, noise=sigma, stopped_at_budget=fit.status == BUDGET_STATUS,
                      noise_source=GIVEN if given else "estimated from the residual (RSS / (m - p_eff)) x AR(1) "
                                                       "inflation (1 + rho) / (1 - rho)",
                      autocorrelation=rho, inflation=(1.0 + rho) / (1.0 - rho),
                      n_observations=m, p_eff=p_eff, residual=r, jacobian=J, rss=rss, at_bound=at_bound,
                      n_evaluations=n_evaluations, prior=prior)
    if coordinates is None:
        return fitted
    return with_discrepancy_bars(fitted, coordinates, model_error=model_error, point_size=point_size)


def with_discrepancy_bars(fit: Estimate, coordinates: np.ndarray, *, model_error: np.ndarray | None = None,
                          point_size: int = 3) -> Estimate:
    """``fit`` (Gauss-Newton error bars, as ``estimate`` without coordinates gives it) with the
    error bars ``estimate`` gives with ``coordinates`` and ``model_error``: the model
    discrepancy fitted to its residual (``calibration.discrepancy``), the sandwich covariance.
    The same x and noise: a fit made once serves both (``pipeline.identify_all`` takes the
    cross-validation's reference fit this way when the chosen scale is its scale)."""
    if fit.discrepancy is not None:
        raise ValueError("the fit carries discrepancy error bars already")
    if point_size != 3:
        raise ValueError(f"discrepancy error bars need 3 angles a point, got point_size={point_size}")
    discrepancy = fit_discrepancy(fit.residual, fit.jacobian, fit.x, fit.prior.mean, fit.prior.std, coordinates,
                                  noise=fit.noise if fit.noise_source == GIVEN else None, model_error=model_error)
    covariance = sandwich_covariance(fit.covariance, fit.jacobian, fit.noise, fit.prior.precision,
                                     discrepancy.covariance)
    std = np.where(np.isfinite(fit.std), np.sqrt(np.maximum(np.diag(covariance), 0.0)), np.inf)
    return dataclasses.replace(fit, covariance=covariance, std=std, discrepancy=discrepancy,
                               gauss_newton_covariance=fit.covariance)


def with_model_error(fit: Estimate, coordinates: np.ndarray, model_error: np.ndarray) -> Estimate:
    """``fit`` with its error bars recomputed to carry a model-error budget (K, m) [residual
    units] (``estimate``'s ``model_error``; for a budget that needs the estimate first, e.g. the
    prototype run at it): the same x, the discrepancy refitted with the budget as a known
    covariance, the sandwich on the same weighting."""
    if fit.gauss_newton_covariance is None:
        raise ValueError("the fit has Gauss-Newton error bars; estimate it with coordinates first")
    white = dataclasses.replace(fit, covariance=fit.gauss_newton_covariance, discrepancy=None,
                                gauss_newton_covariance=None)
    return with_discrepancy_bars(white, coordinates, model_error=model_error)


def held_out_folds(leg: Sequence[int], n_folds: int = 5) -> list[np.ndarray]:
    """Index sets (points) of held-out whole legs: the trajectory's own legs when it has at
    least 3 (the start point, leg 0, joins none: it is always trained on), consecutive legs
    merged into ``n_folds`` groups when there are more; else ``n_folds`` contiguous blocks."""
    leg = np.asarray(leg)
    labels = [label for label in dict.fromkeys(leg.tolist()) if label != 0]
    if len(labels) >= 3:
        groups = np.array_split(np.array(labels, dtype=object), min(n_folds, len(labels)))
        return [np.flatnonzero(np.isin(leg, list(group))) for group in groups]
    blocks = np.array_split(np.arange(leg.size), min(n_folds, leg.size))
    return [b for b in blocks if b.size]


@dataclass(frozen=True, kw_only=True)
class CrossValidation:
    """scales tried; held_out_rms (n_scales,) [residual units] RMS of the held-out residuals
    over all folds; best: the chosen scale (the narrowest within one standard error of the
    lowest held-out RMS, ``one_standard_error_choice``); n_folds; reference: the fit on all
    points at reference_scale that set the folds' noise (None when the noise was given)."""

    scales: tuple[float, ...]
    held_out_rms: np.ndarray
    best: float
    n_folds: int
    reference: Estimate | None = None
    reference_scale: float = 1.0


def choose_prior_scale(residuals_for: Callable[[np.ndarray], Residuals], n_params: int, folds: Sequence[np.ndarray],
                       n_points: int, *, scales: Sequence[float] = PRIOR_SCALES, noise: float | None = None,
                       point_size: int = 3, reference_scale: float = 1.0,
                       on_fit: Callable[[], None] = lambda: None, x0: np.ndarray | None = None,
                       budget_restarts: int = 0) -> CrossValidation:
    """The prior scale by held-out RMS: the narrowest within one standard error of the lowest.

    residuals_for(points (k,) int) -> batched residuals on those points only, (n, k *
    point_size); folds: held-out point sets (``held_out_folds``). For each scale and fold the
    estimate is fitted on the other points and scored on the fold.
    Without a given noise, one fit on all points at ``reference_scale`` (from the prior mean,
    or ``x0`` [unit box]) estimates it first and the fold fits use that value (one fit each
    instead of up to ``max_noise_rounds``: the noise sets the data's weight against the prior,
    the quantity the scale trades against, so every scale is scored at the same noise), and
    start where it ended: a held-out fit is then a few steps from its own minimum (measured,
    docs/calibration.md "Session 35": from ``x0`` 13 of the README run's 18 fold fits stopped
    at their budget, and the scores were those of fits on their way). With a given noise they
    start at ``x0``. Each fold fit gets 50 Jacobians' worth of rows. on_fit() after each fit
    (progress).
    budget_restarts: the reference fit's (``estimate``), which is then the fit on all points at
    that scale (``CrossValidation.reference``).
    """
    all_points = np.arange(n_points)
    scales = tuple(sorted(scales))  # narrowest first: the one-standard-error rule prefers it
    reference = None
    if noise is None:
        reference = estimate(residuals_for(all_points), uniform_prior(n_params, reference_scale),
                             point_size=point_size, x0=x0, budget_restarts=budget_restarts)
        noise = reference.noise
        on_fit()
    scores, errors = [], []
    for scale in scales:
        fold_squares, fold_counts = [], []
        for fold in folds:
            train = np.setdiff1d(all_points, fold)
            fit = estimate(residuals_for(train), uniform_prior(n_params, scale), noise=noise, point_size=point_size,
                           max_evaluations=50 * (n_params + 2), x0=x0 if reference is None else reference.x)
            on_fit()
            r = np.asarray(residuals_for(fold)(fit.x[None]), float)[0]
            fold_squares.append(float(r @ r))
            fold_counts.append(r.size)
        score, error = _held_out_rms_and_error(np.array(fold_squares), np.array(fold_counts))
        scores.append(score)
        errors.append(error)
    scores = np.array(scores)
    return CrossValidation(scales=tuple(scales), held_out_rms=scores,
                           best=float(scales[one_standard_error_choice(scores, np.array(errors))]), n_folds=len(folds),
                           reference=reference, reference_scale=float(reference_scale))


def _held_out_rms_and_error(fold_squares: np.ndarray, fold_counts: np.ndarray) -> tuple[float, float]:
    """The pooled held-out RMS over the folds and its standard error from the folds' spread:
    the folds' mean squares scatter by s; the pooled mean square then has a standard error
    s / sqrt(K), and its square root (the RMS) half that relative error (delta method). One
    fold: no spread to measure, error 0."""
    rms = math.sqrt(float(fold_squares.sum()) / max(int(fold_counts.sum()), 1))
    if fold_squares.size < 2:
        return rms, 0.0
    mean_squares = fold_squares / np.maximum(fold_counts, 1)
    error_ms = float(np.std(mean_squares, ddof=1)) / math.sqrt(fold_squares.size)
    return rms, error_ms / (2.0 * rms) if rms > 0 else 0.0


def one_standard_error_choice(scores: np.ndarray, errors: np.ndarray) -> int:
    """Index of the first (narrowest, scales ascending) prior scale whose held-out RMS is
    within one standard error of the lowest one (the one-standard-error rule of
    cross-validation, Hastie, Tibshirani & Friedman, ESL 7.10): a wider prior must earn its
    place by more than the held-out score's own sampling error. Measured why (issue 26,
    session 16): with a 0.4 % change of the prototype's FEM grid the lowest score flipped from
    scale 1 to 2 on 1.54 against 1.57 urad, and the identified base parameters went from z RMS
    ~1 to 9.7 with it; the scale-2 score ranged 1.54-3.8 urad over six such runs."""
    best = int(np.argmin(scores))
    return int(np.flatnonzero(scores <= scores[best] + errors[best])[0])
