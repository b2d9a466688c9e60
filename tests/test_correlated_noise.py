"""The correlated-noise test, the detection statistic of the library's noise effects
(air_turbulence; validation/diagnosis/correlated.py, docs/diagnosis.md "Correlated noise"):
its false-alarm rate under white noise, its power on an AR(1) that does not repeat, and that
what repeats or what a deterministic term explains is not counted."""

import numpy as np
import pytest

from flexcal.validation.diagnosis.correlated import NOISE_ALPHA, correlated_noise, separated_pairs
from flexcal.validation.effects.chain import ar1_series

SIGMA = np.full(3, 0.5e-6)  # [rad] the benchmark's sensor noise


def _two_cycles(k=77, seed=0):
    """Inputs (2k, 3) [m] and travel directions of k distinct postures measured twice; time (2k,) [s]."""
    rng = np.random.default_rng(seed)
    one = rng.uniform(-5e-3, 5e-3, size=(k, 3))
    inputs = np.vstack([one, one])
    direction = np.ones_like(inputs)
    return inputs, direction, np.arange(2 * k) * 2.0


def test_pairs_are_as_far_apart_as_the_repeats_allow():
    inputs = np.array([[0.0, 0, 0], [1e-3, 0, 0], [1e-3, 0, 0], [2e-3, 0, 0], [1e-3, 0, 0], [1e-3, 0, 0],
                       [0.0, 0, 0]])
    earlier, later = separated_pairs(inputs, np.ones_like(inputs))
    # posture 1 mm read at 1, 2, 4, 5: (1, 4) and (2, 5), each reading once; the zero posture (0, 6)
    assert list(zip(earlier.tolist(), later.tolist())) == [(1, 4), (2, 5), (0, 6)]
    other_direction = np.ones_like(inputs)
    other_direction[4:] = -1.0  # a reading in the other travel direction is not a repeat: (1, 2) and (4, 5)
    assert separated_pairs(inputs, other_direction)[0].tolist() == [1, 4]


def test_false_alarm_rate_under_white_noise_is_at_most_alpha():
    """1500 white-noise files (77 postures x2, a ramp and a smooth regressor removed): the test at
    alpha = 0.02 (a rate measurable with 1500 files) rejects at most that often."""
    inputs, direction, time = _two_cycles()
    rng = np.random.default_rng(1)
    regressors = np.stack([np.outer(time, np.ones(3)) * 1e-9, np.cos(time / 40.0)[:, None] * np.ones(3) * 1e-6],
                          axis=-1)
    rejections = sum(correlated_noise(rng.normal(size=(154, 3)) * SIGMA, SIGMA, inputs, direction, regressors,
                                      alpha=0.02)["correlated"] for _ in range(1500))
    # binomial standard error of a 0.02 rate over 1500 files is 0.0036: 0.02 + 3 of them (the regression
    # biases r negative, so the true rate is below alpha)
    assert rejections / 1500 <= 0.02 + 3 * np.sqrt(0.02 * 0.98 / 1500)


def test_an_ar1_that_does_not_repeat_is_found_and_a_repeating_signal_is_not():
    inputs, direction, time = _two_cycles()
    rng = np.random.default_rng(2)
    noise = rng.normal(size=(154, 3)) * SIGMA
    turbulence = 3 * SIGMA * ar1_series(time, 60.0, seed=5)  # air_turbulence at 3x the noise
    found = correlated_noise(noise + turbulence, SIGMA, inputs, direction)
    assert found["correlated"] and found["p_value"] < NOISE_ALPHA and found["n_pairs"] == 77
    repeating = np.vstack([turbulence[:77], turbulence[:77]])  # the same shape in both cycles: a function of the posture
    assert not correlated_noise(noise + repeating, SIGMA, inputs, direction)["correlated"]


def test_what_a_deterministic_term_explains_is_removed_first():
    """A slow temperature-like swing that differs between the cycles is correlated noise to the
    test until the term that explains it (its column) is given as a regressor."""
    inputs, direction, time = _two_cycles()
    noise = np.random.default_rng(3).normal(size=(154, 3)) * SIGMA
    swing = np.sin(2 * np.pi * time / 250.0)[:, None] * np.array([2.0, 1.0, 1.5]) * SIGMA
    assert correlated_noise(noise + swing, SIGMA, inputs, direction)["correlated"]
    column = np.sin(2 * np.pi * time / 250.0)[:, None, None] * np.eye(3)[None] * 1e-6  # (n, 3, 3): one per channel
    assert not correlated_noise(noise + swing, SIGMA, inputs, direction, column)["correlated"]


def test_no_repeats_no_test():
    inputs = np.random.default_rng(4).uniform(size=(60, 3))
    result = correlated_noise(np.zeros((60, 3)), SIGMA, inputs, np.ones((60, 3)))
    assert not result["available"] and not result["correlated"] and result["n_pairs"] == 0
