"""Error bars of base-parameter combinations from their profile likelihood (issue #28 item 1).

The sandwich covariance of ``estimation.estimate`` is linear: the misfit along a combination
``c`` of the sources is taken to grow as ``(c x - c x_hat)^2 / (c^T A c)`` (A the Gauss-Newton
posterior). In a curved valley it does not. Measured on the consistent model, table1, seed 3,
0.5 urad (FEM prototype, fresh fit of session 17): the two drive-gain combinations are 18.9 and
12.7 linear standard errors from the truth, yet with every other source re-optimised the MAP
objective at the truth's value of each is only 1.23 and 1.06 above its minimum (0.86 and 0.72
halfway): the data pin these combinations far less than the Jacobian at the estimate says.
(Refits on perturbed data about the estimate, a parametric bootstrap, widened them only 1.1-3x
there: the flatness lies 10-20 linear standard errors out, where noise-sized refits never go.)

The profile: for a combination c and a value v, ``P(v) = min { Phi(x) : c x = v }`` with Phi the
MAP objective the fit minimised (``||r(x) / sigma||^2 + ||(x - mean) / std||^2``, the same
sigma), solved by the same bounded least squares with the constraint as one heavily weighted
row, from the linear conditional point ``x_hat + (v - c x_hat) A c / (c^T A c)``. Its rise
``dP(v) = P(v) - Phi(x_hat)`` is the likelihood-ratio statistic: ``sqrt(dP)`` standard errors.
Probed at ``v = c x_hat +- k s`` (s the linear standard error, k on ``LADDER``) until dP reaches
4 or the unit box ends, each probe bounds the profile's own standard error from below by
``k s / max(sqrt(dP), 1)`` (a probe inside dP < 1 is inside one standard error); the largest
bound over the probes, as a factor f >= 1 on s, widens the sandwich's bar of c by f:
``Cov += (f^2 - 1) (S c)(S c)^T / (c^T S c)`` (S the sandwich covariance), positive
semi-definite, so no bar narrows. A linear problem gives dP = 4 at k = 2: f = 1, two probes.

Only the reported combinations that are not a source alone are profiled (the sources alone
sit inside the z-score band with the linear bars: 0.79 RMS over 12, session 17): those are
where the valley is. Cost: <= 2 x len(LADDER) constrained fits per combination.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np

from flexcal.calibration.polish import least_squares_polish

__all__ = ["ProfileBars", "with_profile_bars", "profile_factor", "LADDER"]

LADDER = (2.0, 6.0, 18.0, 54.0)  # probe distances [linear standard errors]; 54: a bar at most ~54x the linear one
REACHED = 4.0  # dP at which a side stops: two standard errors of the profile
WIDEN_FROM = 1.05  # a factor below this is the probes' round-off (a linear problem's dP = 4 at k = 2 to ~1e-6), not a valley
CONSTRAINT_WEIGHT = 1e3  # the constraint row's weight per linear standard error (met to 1e-3 s or better)
FD_STEP = 1e-6  # [unit box] as the fit's own (estimation.FD_STEP)


@dataclass(frozen=True, kw_only=True, eq=False)
class ProfileBars:
    """combinations (k, d) [unit box] profiled; factors (k,) f >= 1 on each one's bar; probes:
    per combination the (k, dP) pairs measured; added (d, d) [unit box^2] the covariance added;
    n_fits the constrained fits run."""

    combinations: np.ndarray
    factors: np.ndarray
    probes: tuple
    added: np.ndarray
    n_fits: int

    def as_dict(self) -> dict:
        return {"factors": self.factors.tolist(), "n_fits": self.n_fits,
                "probes": [[[float(k), float(dp)] for k, dp in p] for p in self.probes],
                "what": "profile likelihood of each base combination not identified alone: probes at +-k linear "
                        "standard errors (k in 2, 6, 18, 54) with the other sources re-optimised; the bar widened "
                        "to the largest k / max(sqrt(rise), 1) (flexcal.calibration.profile_bars)"}


def profile_factor(probes) -> float:
    """f >= 1 from probes [(k, dP), ...]: the largest lower bound k / max(sqrt(dP), 1)."""
    return max([1.0] + [k / max(np.sqrt(max(dp, 0.0)), 1.0) for k, dp in probes])


def with_profile_bars(fit, residuals: Callable[[np.ndarray], np.ndarray], combinations: np.ndarray, *,
                      ladder: tuple[float, ...] = LADDER, max_evaluations: int | None = None,
                      on_fit: Callable[[], None] = lambda: None):
    """``fit`` (``estimation.Estimate``, with the Gauss-Newton covariance kept) with the bars of
    ``combinations`` (k, d) [unit box] widened by their profile likelihood (module doc);
    residuals: the fit's residual function ``r(X (n, d)) -> (n, m)``."""
    if fit.gauss_newton_covariance is None:
        raise ValueError("the fit has Gauss-Newton error bars; estimate it with coordinates first")
    combinations = np.atleast_2d(np.asarray(combinations, float))
    prior, sigma, x_hat = fit.prior, fit.noise, fit.x
    finite = np.isfinite(prior.std)
    linear = fit.gauss_newton_covariance
    budget = max_evaluations if max_evaluations is not None else 100 * (x_hat.size + 2)

    def objective_rows(X: np.ndarray) -> np.ndarray:
        r = np.asarray(residuals(X), float) / sigma
        return np.concatenate([r, (X[:, finite] - prior.mean[finite]) / prior.std[finite]], axis=1)

    phi_hat = float(np.sum(objective_rows(x_hat[None])[0] ** 2))
    added = np.zeros_like(linear)
    factors, probes, n_fits = [], [], 0
    for c in combinations:
        s = float(np.sqrt(c @ linear @ c))
        if not s > 0:
            factors.append(1.0)
            probes.append(())
            continue
        step = linear @ c / s ** 2  # x moves by (v - c x_hat) step on the linear conditional path
        seen = []
        for side in (-1.0, 1.0):
            for k in ladder:
                v = float(c @ x_hat) + side * k * s
                start = np.clip(x_hat + (v - c @ x_hat) * step, 0.0, 1.0)

                def constrained(X, v=v, c=c, s=s):
                    return np.concatenate([objective_rows(X), ((X @ c - v) * CONSTRAINT_WEIGHT / s)[:, None]], axis=1)
                found = least_squares_polish(constrained, start, fd_step=FD_STEP, ftol=1e-10, xtol=1e-10, gtol=1e-10,
                                             max_evaluations=budget)
                n_fits += 1
                on_fit()
                if abs(c @ found.x - v) > 1e-2 * s:  # the box ends before v: nothing beyond to probe
                    break
                rise = float(np.sum(objective_rows(found.x[None])[0] ** 2)) - phi_hat
                seen.append((k, rise))
                if rise >= REACHED * (1.0 - 1e-3):  # 1e-3: the constrained fit's own tolerance on the rise
                    break
        f = profile_factor(seen)
        factors.append(f if f > WIDEN_FROM else 1.0)
        probes.append(tuple(seen))
        if f > WIDEN_FROM:
            sc = fit.covariance @ c
            added += (f ** 2 - 1.0) * np.outer(sc, sc) / float(c @ sc)
    covariance = fit.covariance + added
    std = np.where(np.isfinite(fit.std), np.sqrt(np.maximum(np.diag(covariance), 0.0)), np.inf)
    bars = ProfileBars(combinations=combinations, factors=np.array(factors), probes=tuple(probes), added=added,
                       n_fits=n_fits)
    return dataclasses.replace(fit, covariance=covariance, std=std, profile_bars=bars)
