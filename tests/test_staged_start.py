"""A consistent model's fits start at the second-order model's estimate on the same data
(``calibration.staged_start``, ``IdentificationSettings.staged``): the consistent model's
surface has a worse basin the prior mean can fall into (docs/model.md "Session 21").

The FEM segment provider is replaced by the closed-form one (``closed_form_segments``): the
spaces and the wiring are under test here; the minimum it finds on the FEM prototype is the
slow main-job test's (tests/test_verify_cli.py)."""

import dataclasses

import numpy as np

import flexcal.calibration.estimation as estimation
from flexcal.calibration.offset_chart import offset_chart
import flexcal.calibration.pipeline as pipeline
from flexcal.calibration.pipeline import IdentificationSettings, identify_all
from flexcal.calibration.problem import CalibrationProblem
from flexcal.calibration.staged_start import is_consistent, second_order_form
from flexcal.model.trajectory import standard_trajectory
from test_model_option import _space, closed_form_segments  # noqa: F401 (a fixture)


def test_the_second_order_form_is_what_model_second_order_builds(closed_form_segments):
    consistent, second = _space("--model", "consistent"), _space("--model", "second-order")
    assert is_consistent(consistent) and not is_consistent(second)
    assert dataclasses.asdict(second_order_form(consistent)) == dataclasses.asdict(second)
    assert not is_consistent(second_order_form(consistent))


def _recorded_fits(monkeypatch, space):
    """Run identify_all's fits capped at two Jacobians each; returns [(x0, fitted x)] in order."""
    calls = []
    real = estimation.estimate

    def recording(residuals, prior, **kwargs):
        fit = real(residuals, prior, **{**kwargs, "max_evaluations": 2 * (space.n_params + 1)})
        calls.append((kwargs.get("x0"), fit.x))
        return fit
    monkeypatch.setattr(pipeline, "estimate", recording)
    monkeypatch.setattr(estimation, "estimate", recording)
    return calls


def _data(space):
    trajectory = standard_trajectory()
    x_true = np.random.default_rng(5).uniform(0.3, 0.7, space.n_params)
    angles = CalibrationProblem(space=space, inputs=trajectory.inputs,
                                angles=np.zeros_like(trajectory.inputs)).model_angles(x_true[None])[0][0]
    return trajectory.inputs, angles, trajectory.leg


def test_a_consistent_fit_starts_at_the_second_order_estimate(monkeypatch, closed_form_segments):
    space = _space("--model", "consistent")
    inputs, angles, leg = _data(space)
    calls = _recorded_fits(monkeypatch, space)
    lines = []
    identify_all(space, inputs, angles, leg, IdentificationSettings(n_folds=2, scales=(1.0,)), log=lines.append)
    half = len(calls) // 2
    # per stage: the noise fit, the folds; the noise fit, on all points at the one scale, is the
    # stage's estimate (calibration.estimation.CrossValidation.reference)
    assert len(calls) == 2 * half and half == 3
    # each stage's held-out fits start where its reference fit ended
    for stage in (calls[:half], calls[half:]):
        for x0, _ in stage[1:]:
            np.testing.assert_array_equal(x0, stage[0][1])
    assert calls[0][0] is None  # the second-order stage: from the prior mean
    start = calls[0][1]  # the second-order stage's estimate
    assert np.allclose(calls[half][0], np.clip(start, 0.0, 1.0), atol=1e-12)  # unit-box round trip of its SI values
    assert any(line.startswith("start: the second-order model's estimate") for line in lines)


def test_no_stage_when_told_or_given_a_start_or_not_consistent(monkeypatch, closed_form_segments):
    consistent, second = _space("--model", "consistent"), _space("--model", "second-order")
    inputs, angles, leg = _data(consistent)
    calls = _recorded_fits(monkeypatch, consistent)
    quick = IdentificationSettings(prior_scale=1.0)
    identify_all(consistent, inputs, angles, leg, dataclasses.replace(quick, staged=False))
    identify_all(second, inputs, angles, leg, quick)
    assert [x0 for x0, _ in calls] == [None, None]  # one fit each, from the prior mean
    calls.clear()
    start = consistent.full_values(consistent.from_unit(np.full(consistent.n_params, 0.25)))
    identify_all(consistent, inputs, angles, leg, dataclasses.replace(quick, start=start))
    given = offset_chart(consistent.names).from_space(np.full(consistent.n_params, 0.25))  # the estimator's coordinates
    assert len(calls) == 1 and np.allclose(calls[0][0], given, atol=1e-12)  # the given start, no stage; round-off


def test_the_fits_run_the_model_on_the_threads_asked_and_get_the_same_bits(monkeypatch, closed_form_segments):
    """``IdentificationSettings.n_threads`` reaches every model call of the fits (the problem over
    all points, the cross-validation folds', the second-order stage's), and the estimate is the
    same to the bit on 1 and 2 threads (the compiled solve is per candidate, ``model.forward``)."""
    from test_model_threads_cli import recorded_model_threads

    space = _space("--model", "consistent")
    inputs, angles, leg = _data(space)
    _recorded_fits(monkeypatch, space)
    asked = recorded_model_threads(monkeypatch)
    found = {}
    for threads in (1, 2):
        asked.clear()
        found[threads] = identify_all(space, inputs, angles, leg,
                                      IdentificationSettings(n_folds=2, scales=(1.0,), n_threads=threads))
        assert asked and set(asked) == {threads}
    np.testing.assert_array_equal(found[2].values, found[1].values)
    np.testing.assert_array_equal(found[2].std, found[1].std)


def test_the_threads_are_a_positive_count():
    import pytest

    for threads in (0, -1, 1.5):
        with pytest.raises(ValueError, match="n_threads"):
            IdentificationSettings(n_threads=threads)
