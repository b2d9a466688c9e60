"""Compiled loops of the effects' first-order recurrences along a trajectory (numba).

``terms.relaxed`` and ``chain.settling_error`` step a state point by point; in numpy each step
is a few row operations of 3 numbers, ~3-6 us of interpreter time, and a diagnosis evaluates
them ~70,000 times (28 % of table1's step-loss case, cProfile, session 35). The loops here
are the same operations in the same order on the same inputs (every ``exp`` is taken by
numpy before the loop), so they give the same bits (``tests/test_effects_recurrences.py``).
"""

from __future__ import annotations

import numba
import numpy as np

# the files whose code or constants these cached kernels compile in, with a digest of their text
# (numba keys its cache by this file's text only: tests/test_numba_cache_keys.py)
SOURCES_COMPILED_IN = {}

__all__ = ["lag", "settling"]


@numba.njit(cache=True)
def lag(series: np.ndarray, decay: np.ndarray) -> np.ndarray:
    """y (n, m): y_0 = series_0, y_k = series_{k-1} + (y_{k-1} - series_{k-1}) decay_{k-1}
    (decay (n - 1,))."""
    n, m = series.shape
    y = np.empty_like(series)
    for j in range(m):
        y[0, j] = series[0, j]
    for k in range(1, n):
        for j in range(m):
            y[k, j] = series[k - 1, j] + (y[k - 1, j] - series[k - 1, j]) * decay[k - 1]
    return y


@numba.njit(cache=True)
def settling(theta: np.ndarray, q: np.ndarray, tau: np.ndarray, window: np.ndarray, tail: np.ndarray,
             averaged: bool) -> np.ndarray:
    """reading (n, 3): state_k = s_k q_{k-1}, s_k = state_{k-1} + theta_{k-1} - theta_k; the
    reading is state_k, or with ``averaged`` s_k tau / window_{k-1} tail_{k-1} (q, tail (n - 1,
    3); tau (3,); window (n - 1,))."""
    n, m = theta.shape
    state = np.zeros((n, m))
    reading = np.zeros((n, m))
    for k in range(1, n):
        for j in range(m):
            start = state[k - 1, j] + theta[k - 1, j] - theta[k, j]
            state[k, j] = start * q[k - 1, j]
            if averaged:
                reading[k, j] = start * tau[j] / window[k - 1] * tail[k - 1, j]
            else:
                reading[k, j] = state[k, j]
    return reading
