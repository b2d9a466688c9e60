"""The thermal term on a file with repeated time stamps (two readings in the same second):
finite, no RuntimeWarning (it divided by the zero time step before)."""

import warnings

import numpy as np

from flexcal.validation.effects.terms import time_rate


def test_repeated_time_stamps_give_a_finite_rate_without_warnings():
    time = np.array([0.0, 0.0, 2.0, 2.0, 4.0, 4.0, 6.0])
    temperature = 20.0 + 0.01 * time
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rate = time_rate(temperature, time)
    np.testing.assert_allclose(rate, 0.01, rtol=1e-12)  # a linear ramp: its slope everywhere (round-off only)


def test_distinct_time_stamps_match_numpy_gradient():
    rng = np.random.default_rng(0)
    time = np.cumsum(rng.uniform(0.5, 2.0, 20))
    values = rng.normal(size=20)
    np.testing.assert_allclose(time_rate(values, time), np.gradient(values, time), rtol=1e-12)  # the same formula
    assert np.all(time_rate(values, np.zeros(20)) == 0.0)  # one stamp: no rate to tell


def test_a_jacobian_of_rank_zero_is_analysed_not_an_index_error():
    """diagnose of a file far beyond the mount (inputs 90x the stroke) ended in 'internal error:
    IndexError' when the identifiable subset was empty."""
    from flexcal.calibration.identifiability import analyze_jacobian

    report = analyze_jacobian(np.zeros((6, 2)), ["a", "b"])
    assert report.rank == 0 and report.condition_number_subset == float("inf")
