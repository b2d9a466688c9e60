"""Local least-squares polish of an identified parameter vector.

``least_squares_polish`` runs ``scipy.optimize.least_squares(method="trf")`` on the
unit box from a start point (typically the PSO's best particle) and counts every
residual evaluation, including the finite-difference Jacobians that trf's ``nfev``
leaves out. With ``batched_jacobian=True`` each Jacobian is one batched call of the
d perturbed points (the unperturbed one is reused from the preceding residual call
when scipy asks for the Jacobian at that point, which it always does in trf).

``batched_jacobian_fd`` is the same forward/central difference as a free function
(also used by ``flexcal.calibration.identifiability``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["PolishResult", "least_squares_polish", "polish_candidates", "norm_sum_polish", "batched_jacobian_fd",
           "EvaluationCounter", "BUDGET_STATUS"]

BUDGET_STATUS = -10  # PolishResult.status of a fit stopped by its evaluation budget

Residuals = Callable[[np.ndarray], np.ndarray]


class EvaluationCounter:
    """Wrap a batched function ``g(X (n, d)) -> (n, ...)``, counting rows and calls.

    Raises ``BudgetExhausted`` when a call would exceed ``max_evaluations`` rows.
    """

    def __init__(self, function: Residuals, max_evaluations: int | None = None) -> None:
        self.function = function
        self.max_evaluations = max_evaluations
        self.n_evaluations = 0
        self.n_calls = 0

    def __call__(self, X: np.ndarray) -> np.ndarray:
        X = np.atleast_2d(X)
        if self.max_evaluations is not None and self.n_evaluations + X.shape[0] > self.max_evaluations:
            raise BudgetExhausted(self.n_evaluations)
        self.n_evaluations += X.shape[0]
        self.n_calls += 1
        return np.asarray(self.function(X), float)


class BudgetExhausted(RuntimeError):
    """The evaluation budget of an ``EvaluationCounter`` is used up."""


def batched_jacobian_fd(residuals: Residuals, x: np.ndarray, *, step: float = 1.5e-8, scheme: str = "forward",
                        lower: np.ndarray | float = 0.0, upper: np.ndarray | float = 1.0,
                        r0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Finite-difference Jacobian of ``residuals`` at x (d,) in one batched call.

    residuals: ``r(X (n, d)) -> (n, m)``. step: absolute step [units of x]; forward
    steps flip to backward at the upper bound (and central shrinks to stay inside).
    r0: r(x) (m,) if known (forward scheme then evaluates d points, else d + 1).
    Returns (J (m, d), r0 (m,)). Forward error ~ step x curvature; central ~ step^2.
    """
    x = np.asarray(x, float)
    d = x.size
    lower = np.broadcast_to(np.asarray(lower, float), (d,))
    upper = np.broadcast_to(np.asarray(upper, float), (d,))
    if scheme == "forward":
        h = np.where(x + step <= upper, step, -step)
        points = x + np.diag(h)
        if r0 is None:
            values = residuals(np.vstack([x, points]))
            r0, rp = values[0], values[1:]
        else:
            rp = residuals(points)
        J = (rp - r0).T / h
    elif scheme == "central":
        h_plus = np.minimum(step, upper - x)  # one-sided where a bound is nearer than step
        h_minus = np.minimum(step, x - lower)
        if np.any(h_plus + h_minus <= 0):
            raise ValueError("a bound interval is empty at x: cannot take a finite difference")
        values = residuals(np.vstack([x + np.diag(h_plus), x - np.diag(h_minus)] + ([x[None]] if r0 is None else [])))
        r0 = values[2 * d] if r0 is None else r0
        r_plus = np.where((h_plus > 0)[:, None], values[:d], r0)
        r_minus = np.where((h_minus > 0)[:, None], values[d:2 * d], r0)
        J = (r_plus - r_minus).T / (h_plus + h_minus)
    else:
        raise ValueError(f"scheme={scheme!r} must be 'forward' or 'central'")
    return J, np.asarray(r0, float)


@dataclass(frozen=True, kw_only=True)
class PolishResult:
    """Outcome of ``least_squares_polish``.

    x (d,) [unit box]; cost = 0.5 sum r^2 at x; rms = sqrt(mean r^2); x0 (d,) and
    cost0: the start; n_evaluations: every residual row evaluated (residual calls and
    all Jacobian points); nfev / njev: scipy's counts; status / message: scipy's, or
    status -10 "evaluation budget exhausted" (x is then the best point seen); wall_s [s].
    """

    x: np.ndarray
    cost: float
    rms: float
    x0: np.ndarray
    cost0: float
    n_evaluations: int
    nfev: int
    njev: int
    status: int
    message: str
    wall_s: float


def least_squares_polish(residuals: Residuals, x0_unit: np.ndarray, *, lower: np.ndarray | float = 0.0,
                         upper: np.ndarray | float = 1.0, batched_jacobian: bool = True,
                         fd_step: float = 1.5e-8, fd_scheme: str = "forward", max_evaluations: int | None = None,
                         ftol: float = 1e-12, xtol: float = 1e-12, gtol: float = 1e-12,
                         loss: str = "linear", f_scale: float = 1.0) -> PolishResult:
    """Polish x0 (d,) by bounded trust-region least squares on ``residuals``.

    residuals: ``r(X (n, d)) -> (n, m)`` on the unit box (scaled so that 1 is the
    noise level if you want ``rms`` in noise units). lower / upper: the box (default
    [0, 1]). batched_jacobian: our one-call finite differences (``fd_step``,
    ``fd_scheme``); False lets scipy do its own '2-point' differences, one call per
    point. max_evaluations: hard budget of residual rows (the best point seen is
    returned when it runs out). Tolerances: scipy's; 1e-12 lets trf run to the
    precision the model allows.
    """
    from scipy.optimize import least_squares

    start = time.perf_counter()
    x0 = np.asarray(x0_unit, float).reshape(-1)
    d = x0.size
    lo = np.broadcast_to(np.asarray(lower, float), (d,)).copy()
    hi = np.broadcast_to(np.asarray(upper, float), (d,)).copy()
    if np.any(hi <= lo):
        raise ValueError("every upper bound must exceed its lower bound")
    x0 = np.clip(x0, lo, hi)
    counter = EvaluationCounter(residuals, max_evaluations)
    last = {"x": None, "r": None}
    best = {"x": x0.copy(), "cost": np.inf}

    def remember(x, r):
        last["x"], last["r"] = x.copy(), r
        cost = 0.5 * float(r @ r)
        if cost < best["cost"]:
            best["x"], best["cost"] = x.copy(), cost

    def fun(x):
        if last["x"] is not None and np.array_equal(last["x"], x):
            return last["r"]
        r = counter(x[None])[0]
        remember(x, r)
        return r

    def jac(x):
        r0 = last["r"] if last["x"] is not None and np.array_equal(last["x"], x) else None
        J, r = batched_jacobian_fd(counter, x, step=fd_step, scheme=fd_scheme, lower=lo, upper=hi, r0=r0)
        if r0 is None:
            remember(x, r)
        return J

    r_start = fun(x0)
    cost0 = 0.5 * float(r_start @ r_start)
    try:
        res = least_squares(fun, x0, jac=jac if batched_jacobian else "2-point", bounds=(lo, hi), method="trf",
                            ftol=ftol, xtol=xtol, gtol=gtol, loss=loss, f_scale=f_scale, x_scale=1.0, max_nfev=None)
        x, r = res.x, np.asarray(res.fun, float)
        cost = 0.5 * float(r @ r)
        status, message, nfev, njev = res.status, res.message, res.nfev, res.njev or 0
    except BudgetExhausted:
        x, cost = best["x"], best["cost"]
        status, message, nfev, njev = BUDGET_STATUS, "evaluation budget exhausted", 0, 0
    m = r_start.size
    return PolishResult(x=x, cost=cost, rms=float(np.sqrt(2.0 * cost / m)), x0=x0, cost0=cost0,
                        n_evaluations=counter.n_evaluations, nfev=int(nfev), njev=int(njev), status=int(status),
                        message=str(message), wall_s=time.perf_counter() - start)


def norm_sum_polish(residuals: Residuals, x0_unit: np.ndarray, *, point_size: int = 3, rounds: int = 8,
                    max_evaluations: int | None = None, floor: float = 1e-12, **options) -> PolishResult:
    """Minimize the paper's Eq. 13 -- the *sum of per-point norms* ``sum_i ||r_i||`` -- by
    iteratively reweighted least squares from x0 (d,) (Weiszfeld's scheme).

    ``least_squares_polish`` minimizes the sum of squares, whose minimizer is not Eq. 13's
    when the model cannot fit the curve exactly; each round here solves the weighted
    problem ``sum_i ||r_i||^2 / max(||r_i^(k)||, floor)`` from the last point, which
    decreases Eq. 13 monotonically (majorization: sqrt(a) <= (a/b + b) / 2) and stops
    when a round no longer lowers it by 1e-9 relative. residuals: ``r(X (n, d)) -> (n, m)``
    with m = n_points * point_size, points major; floor [units of r] keeps exact-fit points
    finite. Returns the ``PolishResult`` of the last accepted round with ``cost`` = Eq. 13
    sum over points and n_evaluations of all rounds; options go to ``least_squares_polish``.
    """
    x = np.asarray(x0_unit, float).reshape(-1)
    counter = EvaluationCounter(residuals, max_evaluations)
    start = time.perf_counter()

    def norms(r: np.ndarray) -> np.ndarray:
        if r.shape[-1] % point_size:
            raise ValueError(f"residual length {r.shape[-1]} is not a multiple of point_size={point_size}")
        return np.linalg.norm(r.reshape(r.shape[0], -1, point_size), axis=-1)

    try:
        r0 = counter(x[None])
    except BudgetExhausted:
        raise ValueError("max_evaluations leaves no room for a single evaluation") from None
    weights = 1.0 / np.sqrt(np.maximum(norms(r0)[0], floor))
    value0 = value = float(norms(r0)[0].sum())
    result, r_best = None, r0[0]
    for _ in range(max(1, int(rounds))):
        w = np.repeat(weights, point_size)
        left = None if max_evaluations is None else max_evaluations - counter.n_evaluations
        if left is not None and left <= 1:
            break
        step = least_squares_polish(lambda X: counter(X) * w, x, max_evaluations=left, **options)
        r = counter(step.x[None])[0] if left is None or left - step.n_evaluations > 1 else None
        if r is None:
            break
        new = float(norms(r[None])[0].sum())
        if new >= value * (1.0 - 1e-9):
            break
        x, value, result, r_best = step.x, new, step, r
        weights = 1.0 / np.sqrt(np.maximum(norms(r[None])[0], floor))
    m = r0.shape[-1]
    return PolishResult(x=x, cost=value, rms=float(np.sqrt(np.mean(r_best ** 2))), x0=np.asarray(x0_unit, float),
                        cost0=value0, n_evaluations=counter.n_evaluations,
                        nfev=0 if result is None else result.nfev, njev=0 if result is None else result.njev,
                        status=0 if result is None else result.status,
                        message=f"Eq. 13 IRLS ({m // point_size} points)", wall_s=time.perf_counter() - start)


def polish_candidates(residuals: Residuals, candidates: np.ndarray, *, max_evaluations: int | None = None,
                      select: Callable[[np.ndarray], np.ndarray] | None = None,
                      **options) -> tuple[PolishResult, tuple[PolishResult, ...], int]:
    """Polish several start points (k, d) in turn and keep the lowest cost.

    candidates: e.g. ``PSOResult.candidates()`` (best first); max_evaluations: budget for
    all polishes together (each gets what the previous left; the rest are skipped when it
    runs out); select: a batched objective ``f(X (k, d)) -> (k,)`` that picks the winner
    (e.g. the Eq. 13 fitness, whose best basin need not be the sum of squares'; its k
    evaluations are added to the count), default the lowest sum of squares; options:
    passed to ``least_squares_polish``. Returns (best result, every result, total
    evaluations).
    """
    candidates = np.atleast_2d(np.asarray(candidates, float))
    if candidates.shape[0] == 0:
        raise ValueError("no candidates to polish")
    results, used = [], 0
    for x0 in candidates:
        left = None if max_evaluations is None else max_evaluations - used
        if left is not None and left <= 1:
            break
        result = least_squares_polish(residuals, x0, max_evaluations=left, **options)
        used += result.n_evaluations
        results.append(result)
    if select is None:
        best = min(results, key=lambda r: r.cost)
    else:
        scores = np.asarray(select(np.array([r.x for r in results])), float)
        used += len(results)
        best = results[int(np.argmin(scores))]
    return best, tuple(results), used

