"""Error bars that carry the model's nonlinearity: refits on perturbed data (issue #28 item 1).

The sandwich covariance of ``estimation.estimate`` is linear: it propagates noise and model
discrepancy through the Jacobian at the estimate. Where the misfit surface is a curved
valley, that is far too narrow along it. Measured (docs/calibration.md 6, session 16): the
consistent model on table1, seed 2, 0.5 urad: two drive-gain base combinations 31 and 27
standard errors from the truth, while the residual RMS is 0.509 urad at the estimate and 0.534
at the truth, and 0.93 midway: a change of chi^2 of ~21 where the linear model predicts ~900.

A parametric bootstrap (randomize-then-optimize in its simplest form) measures the spread the
linearization misses: K refits, each on the fitted curve plus a fresh draw of white noise at
the fit's sigma, from the estimate, with the same prior and weighting. In a linear problem
their covariance is A J^T J A / sigma^2 = A - A P A with A the Gauss-Newton posterior
covariance (J^T J / sigma^2 + P)^-1: never more than A. Their excess over A is the
nonlinearity. In A's whitened coordinates (A = L L^T), T = L^-1 C_b L^-T has eigenvalues <= 1
for a linear problem, up to sampling: with K refits and rank r the largest eigenvalue of K white
draws' second moment lies near the Marchenko-Pastur edge (1 + sqrt(r / K))^2, and above it
often for small r (9 % of 200 draws at r = 5, K = 30); the edge used is the 99th percentile
of that largest eigenvalue, simulated for the r and K at hand (``null_edge``: exact for the
white null, not asymptotic). Every direction above that edge adds its
excess (lambda - 1) L u u^T L^T to the sandwich covariance, so a bar never narrows and widens
only where K refits show, beyond sampling, more spread than the whole linear posterior allows.
Measuring against A rather than A - A P A is the cautious choice: the latter is near singular
where the prior alone pins a direction, and there any coupling would read as a huge excess.
(Measured on the table1 fits of session 15, consistent model, K = 30: seed 2's two drive-gain
combinations z -23.7 / -16.7 -> -2.5 / -3.2, four directions widened by 14-395; seed 1 one
direction at 6.2, just above its edge 4.95; the four sources identified alone within 0.1 of
before.)

C_b is the refits' second moment about the estimate they started from, not their covariance:
a refit mean that drifts from it (the prior's pull along a flat valley) is the estimator's
bias, and an error bar is about the error, bias included (seed 2's combinations -3.2 / -3.7
with the covariance, -2.5 / -3.2 with the second moment). Not carried: the discrepancy's own
nonlinear propagation (only the noise is redrawn), and a valley shaped differently at the truth
than at the estimate (seed 3's two combinations stay at -6.6 / -5.9: one direction widened 10x,
the error 13 linear standard errors).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["RefitSpread", "with_refit_spread", "nonlinear_excess", "null_edge", "REFIT_SEED"]

REFIT_SEED = 2029  # the refits' own noise stream, never a scenario's
NULL_QUANTILE = 0.99  # a linear problem is widened in about 1 run of 100, by a direction just over the edge
NULL_DRAWS = 2000  # simulated white draws for the edge: its 99th percentile to ~1 % (order statistics)


@dataclass(frozen=True, kw_only=True, eq=False)
class RefitSpread:
    """n_refits K; eigenvalues (k,) of the whitened refit second moment above the edge (the
    directions widened, largest last); edge the white-null limit they passed (``null_edge``); added
    (d, d) [unit box^2] the covariance added to the sandwich; refits (K, d) [unit box]."""

    n_refits: int
    eigenvalues: np.ndarray
    edge: float
    added: np.ndarray
    refits: np.ndarray

    def as_dict(self) -> dict:
        return {"n_refits": self.n_refits, "edge": self.edge, "widened_eigenvalues": self.eigenvalues.tolist(),
                "what": "parametric bootstrap: refits on the fitted curve + white noise at the fit's sigma; their "
                        "whitened second moment about the estimate: its excess over the linear one above the 99th percentile of white "
                        "draws' largest eigenvalue "
                        "added to the sandwich (flexcal.calibration.refit_spread)"}


def null_edge(rank: int, n_samples: int, quantile: float = NULL_QUANTILE, draws: int = NULL_DRAWS) -> float:
    """The ``quantile`` of the largest eigenvalue of the second moment X^T X / n of
    ``n_samples`` white draws X (n, rank), simulated (``draws`` times, a fixed seed: the same
    edge every run). Near the Marchenko-Pastur edge (1 + sqrt(rank / n))^2 for large rank."""
    if n_samples < 2 or rank < 1:
        raise ValueError(f"need >= 2 samples and rank >= 1, got {n_samples} and {rank}")
    x = np.random.default_rng([rank, n_samples, 2029]).normal(size=(draws, n_samples, rank))
    small = x @ x.transpose(0, 2, 1) if n_samples < rank else x.transpose(0, 2, 1) @ x  # same nonzero spectrum
    return float(np.quantile(np.linalg.eigvalsh(small / n_samples)[:, -1], quantile))


def nonlinear_excess(refits: np.ndarray, start: np.ndarray, linear: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(added (d, d), eigenvalues above the edge, edge) from refits (K, d), the estimate
    (d,) they started from and the linear covariance (d, d) of the same weighting (module doc).
    A direction the linear covariance does not see (eigenvalue below 1e-12 of the largest) is
    left out."""
    deviations = np.asarray(refits, float) - np.asarray(start, float)
    values, vectors = np.linalg.eigh(np.asarray(linear, float))
    seen = values > max(values.max(initial=0.0), 1e-300) * 1e-12
    root = vectors[:, seen] * np.sqrt(values[seen])  # L, G = L L^T on the seen directions
    whiten = (vectors[:, seen] / np.sqrt(values[seen])).T  # L^-1
    whitened = whiten @ (deviations.T @ deviations / len(deviations)) @ whiten.T
    lam, u = np.linalg.eigh(whitened)
    edge = null_edge(int(seen.sum()), len(deviations))
    above = lam > edge
    directions = root @ u[:, above]
    return (directions * (lam[above] - 1.0)) @ directions.T, lam[above], edge


def with_refit_spread(fit, residuals_for: Callable[[np.ndarray], Callable], fitted: np.ndarray, n_refits: int, *,
                      seed: int = REFIT_SEED, refit: Callable | None = None,
                      on_refit: Callable[[], None] = lambda: None):
    """``fit`` (``estimation.Estimate`` with the sandwich's error bars) with the nonlinear
    excess of ``n_refits`` refits added to its covariance (module doc). residuals_for(angles
    (n, 3) [rad]) -> the residual function of the same problem on those angles; fitted (n, 3)
    [rad] the model's angles at the estimate; refit(residuals, x0) -> refitted x (default:
    ``estimation.estimate`` with the fit's prior and sigma, from the estimate)."""
    from flexcal.calibration.estimation import estimate

    if n_refits < 2:
        raise ValueError(f"n_refits={n_refits} must be >= 2 (a covariance needs two refits)")
    if fit.gauss_newton_covariance is None:
        raise ValueError("the fit has Gauss-Newton error bars; estimate it with coordinates first")
    if refit is None:
        def refit(residuals, x0):
            return estimate(residuals, fit.prior, noise=fit.noise, x0=x0).x
    fitted = np.asarray(fitted, float)
    rng = np.random.default_rng(seed)
    refits = []
    for _ in range(n_refits):
        refits.append(refit(residuals_for(fitted + rng.normal(scale=fit.noise, size=fitted.shape)), fit.x))
        on_refit()
    refits = np.array(refits)
    added, eigenvalues, edge = nonlinear_excess(refits, fit.x, fit.gauss_newton_covariance)
    covariance = fit.covariance + added
    std = np.where(np.isfinite(fit.std), np.sqrt(np.maximum(np.diag(covariance), 0.0)), np.inf)
    spread = RefitSpread(n_refits=n_refits, eigenvalues=eigenvalues, edge=edge, added=added, refits=refits)
    return dataclasses.replace(fit, covariance=covariance, std=std, refit_spread=spread)
