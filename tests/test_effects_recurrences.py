"""The effects' recurrences compiled (``validation/effects/_recurrences.py``) give the bits the
numpy loops they replaced gave (written out here as the reference): the truth of every
synthetic measurement with a lag or a settling sensor, and the diagnosis's terms, unchanged."""

import numpy as np
import pytest

from flexcal.validation.effects.chain import settling_error
from flexcal.validation.effects.terms import relaxed


def _relaxed_loop(series, time, time_constant):
    u = np.asarray(series, dtype=float)
    y = np.empty_like(u)
    y[0] = u[0]
    decay = np.exp(-np.diff(np.asarray(time, dtype=float)) / time_constant)
    for k in range(1, u.shape[0]):
        y[k] = u[k - 1] + (y[k - 1] - u[k - 1]) * decay[k - 1]
    return y


def _settling_loop(angles, time, time_constant, integration_time=0.0):
    theta = np.asarray(angles, dtype=float)
    tau = np.broadcast_to(np.asarray(time_constant, dtype=float), (3,))
    dwell = np.diff(np.asarray(time, dtype=float))
    state = np.zeros_like(theta)
    reading = np.zeros_like(theta)
    for k in range(1, theta.shape[0]):
        start = state[k - 1] + theta[k - 1] - theta[k]
        q = np.exp(-dwell[k - 1] / tau)
        state[k] = start * q
        if integration_time > 0:
            window = min(integration_time, dwell[k - 1])
            reading[k] = start * tau / window * (np.exp(-(dwell[k - 1] - window) / tau) - q)
        else:
            reading[k] = state[k]
    return reading


@pytest.mark.parametrize("n", [1, 2, 3, 77, 301])
def test_the_compiled_recurrences_give_the_loops_bits(n):
    rng = np.random.default_rng(n)
    time = np.cumsum(rng.uniform(0.1, 5.0, n))
    for m in (1, 3):
        series = rng.normal(size=(n, m))
        for tau in (0.3, 20.0, 1e4):
            np.testing.assert_array_equal(relaxed(series, time, tau), _relaxed_loop(series, time, tau))
    angles = 1e-4 * rng.normal(size=(n, 3))
    for tau in (1.5, np.array([0.5, 2.0, 40.0])):
        for integration in (0.0, 0.25, 10.0):  # 10 s: longer than most dwells, the window is the dwell
            np.testing.assert_array_equal(settling_error(angles, time, tau, integration),
                                          _settling_loop(angles, time, tau, integration))
    # a view (a column slice, not contiguous) as the terms pass it
    loads = rng.normal(size=(n, 6))[:, 3:]
    np.testing.assert_array_equal(relaxed(loads, time, 7.0), _relaxed_loop(loads, time, 7.0))
