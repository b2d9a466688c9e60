"""Richardson extrapolation of FEM results over a refinement sequence.

``richardson(h, values)`` fits ``value(h) = limit + c h^p`` through three refinement
levels (cell size h, any unit, decreasing) entry by entry: the observed rate p from the
ratio of successive differences, the limit from the finest two levels. Entries whose
differences change sign (not yet in the asymptotic range, or at round-off) get NaN rate
and the finest value as their limit; entries that do not change get rate inf.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

__all__ = ["Extrapolation", "richardson", "dominant_entries"]


@dataclass(frozen=True, kw_only=True, eq=False)
class Extrapolation:
    """rate (...) [-]: observed order p; limit (...): the extrapolated value; error_estimate
    (...): |limit - finest|, the finest level's estimated discretisation error (same unit
    as the values)."""

    rate: np.ndarray
    limit: np.ndarray
    error_estimate: np.ndarray


def _rate(h: np.ndarray, ratio: float) -> float:
    """p with (h0^p - h1^p) / (h1^p - h2^p) = ratio (ratio > 0 and != 1)."""

    def f(p: float) -> float:
        return (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - ratio

    lo, hi = 1e-3, 20.0
    if f(lo) * f(hi) > 0:
        return float("nan")
    return float(brentq(f, lo, hi, xtol=1e-10))


def richardson(h, values) -> Extrapolation:
    """Three levels: h (3,) cell sizes, coarse to fine; values (3, ...) the results.
    Returns the ``Extrapolation`` of every entry (module docstring)."""
    h = np.asarray(h, float)
    values = np.asarray(values, float)
    if h.shape != (3,) or values.shape[0] != 3 or not np.all(np.diff(h) < 0) or h[-1] <= 0:
        raise ValueError("richardson takes three levels, cell sizes decreasing and > 0, values (3, ...)")
    flat = values.reshape(3, -1)
    rate = np.full(flat.shape[1], np.nan)
    limit = flat[2].copy()
    for k in range(flat.shape[1]):
        d1, d2 = flat[1, k] - flat[0, k], flat[2, k] - flat[1, k]
        if d1 == 0 and d2 == 0:
            rate[k] = np.inf
            continue
        if d1 * d2 <= 0:
            continue  # not monotone: no rate, the finest value stands
        p = _rate(h, d1 / d2)
        if not np.isfinite(p):
            continue
        rate[k] = p
        limit[k] = flat[2, k] + d2 * h[2] ** p / (h[1] ** p - h[2] ** p)
    shape = values.shape[1:]
    return Extrapolation(rate=rate.reshape(shape), limit=limit.reshape(shape),
                         error_estimate=np.abs(limit - flat[2]).reshape(shape))


def dominant_entries(matrix: np.ndarray, fraction: float) -> np.ndarray:
    """Boolean mask (n, n) of the entries at least ``fraction`` of the geometric mean of
    their row's and column's diagonal terms (``DOMINANT_FRACTION`` of
    ``flexcal.validation.reports.fem``): the entries a comparison looks at."""
    matrix = np.asarray(matrix, float)
    scale = np.sqrt(np.outer(np.abs(np.diag(matrix)), np.abs(np.diag(matrix))))
    return np.abs(matrix) >= fraction * scale
