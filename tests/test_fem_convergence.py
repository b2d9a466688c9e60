"""Richardson extrapolation (flexcal.fem.convergence) against sequences of known rate and limit."""

import numpy as np
import pytest

from flexcal.fem.convergence import dominant_entries, richardson


def test_recovers_rate_and_limit_of_a_power_law():
    h = np.array([1 / 2, 1 / 3, 1 / 4])
    limit = np.array([[1.0, -2.5], [3.0, 7.0]])
    rate = np.array([[1.8, 2.0], [4.0, 1.1]])
    values = limit + 0.3 * h[:, None, None] ** rate
    fit = richardson(h, values)
    # exact data: only the root finder's tolerance (xtol 1e-10 on p) and round-off remain
    assert np.allclose(fit.rate, rate, rtol=1e-8)  # the root finder's xtol 1e-10 on p, amplified by log h
    assert np.allclose(fit.limit, limit, rtol=1e-10)  # exact data: round-off of the extrapolation only
    assert np.allclose(fit.error_estimate, 0.3 * h[-1] ** rate, rtol=1e-8)  # follows the rate's 1e-8


def test_non_monotone_entries_keep_the_finest_value():
    fit = richardson([1.0, 0.5, 0.25], [[1.0, 5.0], [2.0, 5.0], [1.5, 5.0]])
    assert np.isnan(fit.rate[0]) and fit.limit[0] == 1.5
    assert fit.rate[1] == np.inf and fit.limit[1] == 5.0


def test_refuses_levels_that_do_not_refine():
    with pytest.raises(ValueError, match="decreasing"):
        richardson([0.5, 1.0, 0.25], np.zeros(3))


def test_dominant_entries_are_relative_to_the_diagonal():
    k = np.array([[1.0, 2e-4], [2e-4, 4.0]])  # 2e-4 / sqrt(1 * 4) = 1e-4 of the diagonal scale
    assert dominant_entries(k, 1e-3).tolist() == [[True, False], [False, True]]
    assert dominant_entries(k, 1e-5).all()
