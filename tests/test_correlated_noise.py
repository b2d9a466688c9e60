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
    """1500 white-noise files (77 postures x2): the test at alpha = 0.02 (a rate measurable with
    1500 files) rejects at most that often."""
    inputs, direction, time = _two_cycles()
    rng = np.random.default_rng(1)
    rejections = sum(correlated_noise(rng.normal(size=(154, 3)) * SIGMA, SIGMA, inputs, direction, time,
                                      alpha=0.02)["correlated"] for _ in range(1500))
    # binomial standard error of a 0.02 rate over 1500 files is 0.0036: 0.02 + 3 of them (removing the
    # constant biases r negative, so the true rate is below alpha)
    assert rejections / 1500 <= 0.02 + 3 * np.sqrt(0.02 * 0.98 / 1500)


def test_an_ar1_that_does_not_repeat_is_found_and_a_repeating_signal_is_not():
    inputs, direction, time = _two_cycles()
    rng = np.random.default_rng(2)
    noise = rng.normal(size=(154, 3)) * SIGMA
    turbulence = 3 * SIGMA * ar1_series(time, 60.0, seed=5)  # air_turbulence at 3x the noise
    found = correlated_noise(noise + turbulence, SIGMA, inputs, direction, time)
    assert found["correlated"] and found["p_value"] < NOISE_ALPHA and found["n_pairs"] == 77
    repeating = np.vstack([turbulence[:77], turbulence[:77]])  # the same shape in both cycles: a function of the posture
    assert not correlated_noise(noise + repeating, SIGMA, inputs, direction, time)["correlated"]


def test_a_deterministic_change_that_does_not_repeat_is_flagged_too():
    """The test cannot tell a random process from a slow deterministic change between the cycles
    (a temperature-like swing): both are correlated and not repeated. Hence the diagnosis answers
    `low` whenever it speaks (docs/diagnosis.md)."""
    inputs, direction, time = _two_cycles()
    noise = np.random.default_rng(3).normal(size=(154, 3)) * SIGMA
    swing = np.sin(2 * np.pi * time / 250.0)[:, None] * np.array([2.0, 1.0, 1.5]) * SIGMA
    assert correlated_noise(noise + swing, SIGMA, inputs, direction, time)["correlated"]
    assert not correlated_noise(noise, SIGMA, inputs, direction, time)["correlated"]


def test_no_repeats_no_test():
    inputs = np.random.default_rng(4).uniform(size=(60, 3))
    result = correlated_noise(np.zeros((60, 3)), SIGMA, inputs, np.ones((60, 3)), np.arange(60.0))
    assert not result["available"] and not result["correlated"] and result["n_pairs"] == 0


def _stub_baseline(n):
    """A baseline of zero model angles with one offset column per channel (the diagnosis's
    baseline is an argument: this keeps the test to the term fits and the noise test)."""
    from flexcal.validation.diagnosis.baseline import BaselineFit

    def baseline(measurement, rng=None, progress=False):
        return BaselineFit(values=np.zeros(45), names=("offset",), model_angles=np.zeros((n, 3)),
                           axial_loads=np.zeros((n, 6)), point_class=("S1",) * n,
                           input_jacobian=np.tile(np.eye(3) * 1e-3, (n, 1, 1)),
                           jacobian=np.ones((n, 3, 1)) * 1e-6, prior_sd=np.ones(1), description="stub", wall_s=0.0)
    return baseline


@pytest.mark.parametrize("turbulence, expected", [(3.0, "air_turbulence"), (0.0, "none")])
def test_the_diagnosis_names_air_turbulence_by_the_noise_test(turbulence, expected):
    """Two cycles of 40 postures (4 legs each), white noise plus an AR(1) of 60 s at 3x the noise:
    air_turbulence, `low` (the test cannot tell it from any other random cause); white noise alone:
    `none`. The diagnosis's own pipeline with a stub baseline (an offset only) and the air_turbulence
    term alone: with this weak baseline drift's rate takes up the AR(1)'s slow wander (closure 0.39,
    measured), which is the held-out route's answer, not the noise test's."""
    from flexcal.validation.diagnosis.diagnose import run_diagnosis
    from flexcal.validation.effects.library import model_term
    from flexcal.validation.measurements import Measurement

    inputs, _, time = _two_cycles(k=40, seed=6)
    n = time.size
    rng = np.random.default_rng(7)
    angles = rng.normal(size=(n, 3)) * SIGMA + turbulence * SIGMA * ar1_series(time, 60.0, seed=8)
    leg = np.concatenate([[0], 1 + np.arange(1, n) * 8 // n])  # 8 legs of 10 points after the start point
    measurement = Measurement(point=np.arange(n), time=time, leg=leg, inputs=inputs, angles=angles)
    report = run_diagnosis(measurement, baseline=_stub_baseline(n), rng=0,
                           terms=[model_term("air_turbulence")]).report
    assert report["top_effect"] == expected, (report["ranking"], report["correlated_noise"])
    assert report["correlated_noise"]["correlated"] == (expected != "none")
    if expected != "none":
        assert report["confidence"] == "low" and report["top_group"] == ["air_turbulence"]
        assert report["detected_by"] == "correlated noise"  # its cosine term did not predict the held-out legs
        from flexcal.validation.reports.diagnose import markdown

        assert "no term was significant" in markdown(report)  # report.md says how the answer was found


def test_a_drift_that_speeds_up_is_not_counted_as_correlated_noise():
    """c t^2 leaves c (t_l - t_e)(t_l + t_e) in a pair's difference: a straight line in the pairs' mean
    time when the repeats are a cycle apart, which the test removes. The curvature here changes the
    reading by 8 noise floors over the run; with only a constant removed (the test before session 22)
    the differences' lag-1 autocorrelations are 0.30 / 0.40 / 0.32 and z 5.2 (measured), past the
    threshold 3.09."""
    inputs, direction, time = _two_cycles()
    noise = np.random.default_rng(9).normal(size=(154, 3)) * SIGMA
    curvature = 8 * SIGMA / time[-1] ** 2  # [rad/s^2]
    result = correlated_noise(noise + np.outer(time**2, curvature), SIGMA, inputs, direction, time)
    assert not result["correlated"]
    # the line removed, what is left is the white differences: z of a standard normal, +-3 is 3 standard deviations
    assert abs(result["z"]) < 3


def _turbulence_or_drift_file(effect: str, k: int = 40):
    """Two cycles of k postures (8 legs of 10 points after the start point): white noise plus either
    an AR(1) of 60 s at 10x the noise or a drift that speeds up (a ramp of 10 noise floors over the
    run and a curvature of 3 more)."""
    from flexcal.validation.measurements import Measurement

    inputs, _, time = _two_cycles(k=k, seed=6)
    n = time.size
    angles = np.random.default_rng(7).normal(size=(n, 3)) * SIGMA
    if effect == "air_turbulence":
        angles += 10 * SIGMA * ar1_series(time, 60.0, seed=8)
    else:
        angles += np.outer(time, 10 * SIGMA / time[-1]) + np.outer(time**2, 3 * SIGMA / time[-1] ** 2)
    leg = np.concatenate([[0], 1 + np.arange(1, n) * 8 // n])
    return Measurement(point=np.arange(n), time=time, leg=leg, inputs=inputs, angles=angles), n


@pytest.mark.parametrize("effect", ["air_turbulence", "drift"])
def test_noise_left_after_a_drift_joins_its_group_and_a_real_drift_keeps_its_answer(effect):
    """With drift and air_turbulence as candidates, drift's ramp takes the slow part of an AR(1) on
    held-out legs and is accepted; what is left is still correlated and not repeated, so the answer is
    the group {drift, air_turbulence} with `low` confidence (the data cannot tell whether a drift is there
    as well). A real drift (with a curvature the drift term does not take) is drift alone."""
    from flexcal.validation.diagnosis.diagnose import run_diagnosis
    from flexcal.validation.effects.library import model_term

    measurement, n = _turbulence_or_drift_file(effect)
    report = run_diagnosis(measurement, baseline=_stub_baseline(n), rng=0,
                           terms=[model_term("drift"), model_term("air_turbulence")]).report
    assert report["accepted_effects"][:1] == ["drift"], report["ranking"]
    if effect == "air_turbulence":
        assert report["correlated_noise"]["correlated"], report["correlated_noise"]
        assert set(report["top_group"]) == {"drift", "air_turbulence"} and report["confidence"] == "low"
        assert report["detected_by"] == "heldout and correlated noise"
    else:
        assert not report["correlated_noise"]["correlated"], report["correlated_noise"]
        assert report["top_group"] == ["drift"] and report["detected_by"] == "heldout"
