"""Effect library (issue #7): injectors in the virtual prototype, model terms, registry,
scenario [[effects]] and the temperature column. Short trajectories, analytic segments;
the fits along the standard trajectory are in test_effect_fits.py."""

import dataclasses

import numpy as np
import pytest

from flexcal.model.trajectory import standard_trajectory
from flexcal.validation.effects.injectors import Drift, LeadError, SensorScale, StepLoss
from flexcal.validation.effects.library import (EFFECT_IDS, LIBRARY, NONE, OUT_OF_LIBRARY_IDS, effects_from_scenario, make_injector, model_term)
from flexcal.validation.effects.magnitude import standard_setting
from flexcal.validation.effects.terms import TERM_CREEP_TIME, path_fraction, relaxed
from flexcal.validation.prototype.mechanism import build_prototype, simulate
from flexcal.validation.effects.hooks import EffectContext, room_temperature
from flexcal.validation.prototype.scenario import load_scenario
from flexcal.validation.prototype.segments import analytic_provider
from flexcal.validation.prototype.truth import as_built, make_truth

SHORT = standard_trajectory(n_points=17)  # both turning points of every leg, ~0.6 s per run
GROWING_WITH_TIME = {"drift", "creep"}  # effects whose size grows with elapsed time


@pytest.fixture(scope="module")
def prototype():
    scenario = load_scenario("table1")  # clearances and friction: the effects meet the full transmission
    mechanism, offsets, drives = as_built(scenario.space, scenario.values)
    return build_prototype(mechanism, [(x0, cl, mu, 2.0) for x0, cl, mu in drives], analytic_provider(),
                           mount_offsets=offsets)


@pytest.fixture(scope="module")
def baseline(prototype):
    return simulate(prototype, SHORT.inputs, time=2.0 * np.arange(SHORT.n_points))


def _run(prototype, effect):
    return simulate(prototype, SHORT.inputs, effects=[effect], time=2.0 * np.arange(SHORT.n_points))


def test_registry_has_every_id():
    assert set(EFFECT_IDS) | set(OUT_OF_LIBRARY_IDS) == set(LIBRARY)
    assert NONE not in LIBRARY and not set(EFFECT_IDS) & set(OUT_OF_LIBRARY_IDS)
    for effect_id in EFFECT_IDS:
        assert model_term(effect_id).id == effect_id
    for effect_id in OUT_OF_LIBRARY_IDS:
        assert LIBRARY[effect_id].term is None
        with pytest.raises(ValueError, match="no model term"):
            model_term(effect_id)


@pytest.mark.parametrize("effect_id", EFFECT_IDS + OUT_OF_LIBRARY_IDS)
def test_every_injector_changes_the_prototype_finitely(prototype, baseline, effect_id):
    effect = make_injector(effect_id, 10.0, 4)
    assert effect.name == effect_id
    run = _run(prototype, effect)
    change = np.abs(run.angles - baseline.angles)
    assert np.all(np.isfinite(run.angles))
    # 10 urad RMS asked: make_injector's linear estimate on the standard 77-point trajectory.
    # Measured here (17 points, table1, seeds 0-5): drift and creep 1.4-3.6 urad RMS (they
    # grow with time and these points last 32 s of the standard 152 s: 10 x 32/152 = 2.1),
    # every other effect 8.6-31 urad (the estimate is linear at the nominal model and misses
    # table1's clearances: up to 3x, lead_error). Windows: those ranges widened by 1.3-1.7x.
    # sensor_settling: the lag error follows the angles' rate, and these points are 2 s apart
    # against the standard trajectory's dwell: measured 46.0-47.0 urad at seeds 0-5, window 1.7x.
    rms = np.sqrt(np.mean(change ** 2))
    low, high = ((1e-6, 5e-6) if effect_id in GROWING_WITH_TIME else (27e-6, 80e-6) if effect_id == "sensor_settling"
                 else (5e-6, 40e-6))
    assert low < rms < high, rms
    assert run.provenance["effects"][0]["name"] == effect_id


@pytest.mark.parametrize("effect_id", EFFECT_IDS + OUT_OF_LIBRARY_IDS)
def test_injectors_are_deterministic_for_a_seed(effect_id):
    assert make_injector(effect_id, 5.0, 11) == make_injector(effect_id, 5.0, 11)
    assert make_injector(effect_id, 5.0, 11) != make_injector(effect_id, 5.0, 12)


def test_sensor_scale_exactly_scales_the_measured_angles(prototype, baseline):
    scale = np.array([1e-3, -2e-3, 3e-3])
    run = _run(prototype, SensorScale(scale=scale))
    np.testing.assert_array_equal(run.true_angles, baseline.true_angles)  # sensor side only
    # the same product: round-off only
    np.testing.assert_allclose(run.angles, baseline.angles * (1 + scale), rtol=1e-14, atol=0)


def test_drift_grows_linearly_in_time_and_steps_at_reversals(prototype, baseline):
    rate = np.array([1e-7, -2e-7, 5e-8])  # [rad/s]
    run = _run(prototype, Drift(rate=rate))
    time = 2.0 * np.arange(SHORT.n_points)
    # the drift is added to ~mrad angles: round-off (1 ulp of 1 mrad = 2e-19 rad)
    np.testing.assert_allclose(run.angles - run.true_angles, np.outer(time, rate), rtol=0, atol=1e-18)
    stepped = _run(prototype, Drift(reversal_step=(1e-6, 0, 0)))
    offsets = (stepped.angles - stepped.true_angles)[:, 0]
    reversals = np.sum(np.diff(SHORT.directions, axis=0) != 0, axis=1)
    np.testing.assert_allclose(offsets, 1e-6 * np.r_[0, np.cumsum(reversals)], rtol=0, atol=1e-18)  # as above
    assert offsets[-1] == pytest.approx(6e-6)  # each actuator reverses twice (at +A and at -A)


def test_step_loss_is_persistent_whole_steps(prototype, baseline):
    effect = StepLoss(events=((1, 0.5e-3, 2),))  # D2 loses 2 steps 0.5 mm into its travel
    run = _run(prototype, effect)
    lost = run.screw_positions[:, 1] - baseline.screw_positions[:, 1]
    path = np.r_[0, np.cumsum(np.abs(np.diff(SHORT.inputs[:, 1])))]
    after = path > 0.5e-3
    assert after.any() and not after.all()
    np.testing.assert_array_equal(lost[~after], 0.0)
    # moving + when it happened (D2 starts upwards): 2 x 5 um against the travel, kept to the end
    np.testing.assert_allclose(lost[after], -2 * effect.step_size, rtol=1e-12)
    assert np.all(run.screw_positions[:, [0, 2]] == baseline.screw_positions[:, [0, 2]])


def test_lead_error_is_periodic_in_the_screw_revolution():
    effect = LeadError(slope=(2e-4, 0, 0), amplitude=(1e-6, 0, 0), phase=(0.7, 0, 0), second=(3e-7, 0, 0))
    context = EffectContext(point_index=0, command=np.zeros(3), direction=np.ones(3), previous=None)
    s = np.linspace(-1e-3, 1e-3, 41)
    error = np.array([effect.modify_screw_position(0, 0.0, x, context) - x for x in s])
    shifted = np.array([effect.modify_screw_position(0, 0.0, x + effect.lead, context) - x - effect.lead for x in s])
    # one revolution later only the linear part has grown (slope x lead); round-off ~1e-19 m
    np.testing.assert_allclose(shifted - error, 2e-4 * effect.lead, rtol=0, atol=1e-15)
    assert effect.modify_screw_position(0, 0.0, 0.0, context) == 0.0  # zero at the home position
    assert np.ptp(error - 2e-4 * s) > 1e-6  # and the periodic part is there


@pytest.mark.parametrize("effect_id", EFFECT_IDS)
def test_model_terms_are_zero_at_zero_and_have_the_right_shape(effect_id):
    data = standard_setting().data
    term = model_term(effect_id)
    # at most 9 a term, but air_turbulence: 8 slow cosines per angle (24), its process has no fewer shapes
    most = 24 if effect_id == "air_turbulence" else 9
    assert term.n_params == len(term.parameter_units) == term.scale.shape[0] and 1 <= term.n_params <= most
    assert set(term.requires) <= set(data.extras)
    zero = term.evaluate(np.zeros(term.n_params), data)
    assert zero.shape == (len(data.time), 3) and np.all(zero == 0.0)
    some = term.evaluate(term.scale, data)
    assert np.all(np.isfinite(some)) and np.abs(some).max() > 0
    with pytest.raises(ValueError, match="parameters"):
        term.evaluate(np.zeros(term.n_params + 1), data)


def test_step_loss_term_is_a_whole_step_at_a_move_and_slides_between_moves():
    data = standard_setting().data
    term = model_term("step_loss")
    fraction, move = path_fraction(data.inputs)
    m = int(np.flatnonzero(np.diff(fraction[:, 1]) > 0)[10]) + 1  # actuator D2's 11th move ends at point m
    lost = 5e-6  # [m] one motor step
    at = np.array([0.0, lost, 0.0, 0.0, fraction[m - 1, 1] - 0.5, 0.0])  # place at the point before the move
    expected = np.einsum("nai,n->na", data.input_jacobian[:, :, 1:2], lost * (np.arange(len(data.time)) >= m))
    # place 0.5 + (f - 0.5) over one move: round-off ~1e-14 relative (was rtol 1e-9)
    np.testing.assert_allclose(term.evaluate(at, data), expected, rtol=1e-12, atol=1e-18)
    # half a move later: the point after the move carries half the step (the place is continuous)
    half = term.evaluate(at + np.array([0, 0, 0, 0, move[1] / 2, 0]), data)
    np.testing.assert_allclose(half[m], expected[m] / 2, rtol=1e-12, atol=1e-18)  # as above
    np.testing.assert_allclose(half[m + 1:], expected[m + 1:], rtol=1e-12, atol=1e-18)  # as above


def test_path_fraction_is_computed_once_per_data_and_cannot_be_changed():
    """TermData.inputs_path_fraction is path_fraction(inputs), the same arrays on every read
    (step_loss reads it on each evaluation), and read-only so no caller changes the cached copy."""
    data = standard_setting().data
    fraction, move = data.inputs_path_fraction
    expected_fraction, expected_move = path_fraction(data.inputs)
    np.testing.assert_array_equal(fraction, expected_fraction)  # the same function on the same inputs: exact
    np.testing.assert_array_equal(move, expected_move)  # exact, as above
    assert data.inputs_path_fraction[0] is fraction
    with pytest.raises(ValueError, match="read-only"):
        fraction[0, 0] = 1.0


def test_creep_term_has_a_free_time_constant():
    data = standard_setting().data
    term = model_term("creep")
    kappa = np.array([1e-6, -1e-6, 5e-7])  # [m/kN]
    load = data.axial_loads[:, 3:] / 1e3
    for log_tau in (-1.0, 0.0, 1.0):
        tau = TERM_CREEP_TIME * np.exp(log_tau)
        expected = np.einsum("nai,ni->na", data.input_jacobian, kappa * (relaxed(load, data.time, tau) - load[0]))
        # the same formula: round-off only
        np.testing.assert_allclose(term.evaluate(np.append(kappa, log_tau), data), expected, rtol=1e-12, atol=1e-20)
    # an absurd time constant is clipped, not overflowed: tau = 20 s e^5 at most
    assert np.all(np.isfinite(term.evaluate(np.append(kappa, 1e4), data)))


def test_effects_from_scenario_builds_and_rejects():
    drift, lead = effects_from_scenario(({"name": "drift", "rate": [1e-8, 0, 0]},
                                         {"name": "lead_error", "magnitude_urad": 5.0, "seed": 2}))
    assert isinstance(drift, Drift) and drift.rate == (1e-8, 0.0, 0.0)
    assert lead == make_injector("lead_error", 5.0, 2)
    for entry, words in [({"name": "wobble"}, ["unknown effect name", "wobble"]),
                         ({"name": "drift", "speed": 1.0}, ["unknown parameter", "speed"]),
                         ({"name": "drift", "magnitude_urad": 1.0, "rate": 1.0}, ["magnitude_urad", "rate"]),
                         ({"name": "drift", "rate": [1.0, 2.0]}, ["rate"])]:
        with pytest.raises(ValueError) as info:
            effects_from_scenario((entry,))
        for word in words:
            assert word in str(info.value)


def test_scenario_effects_reach_the_truth_and_temperature_is_written(tmp_path):
    path = tmp_path / "s.toml"
    plain = 'name = "t"\nseed = 5\ndraw_unset = false\n[trajectory]\nn_points = 13\n'
    path.write_text(plain)
    without = make_truth(load_scenario(str(path)), analytic_provider()).measurement
    path.write_text(plain + '[[effects]]\nname = "lead_error"\nmagnitude_urad = 10.0\nseed = 1\n')
    with_effect = make_truth(load_scenario(str(path)), analytic_provider())
    difference = np.abs(with_effect.measurement.angles - without.angles).max()
    assert difference > 1e-6, difference  # 10 urad RMS asked: > 1 urad somewhere on 13 points
    assert with_effect.measurement.metadata["injected_effects"][0]["name"] == "lead_error"
    # the column is there with or without effects and is the same: it gives nothing away
    np.testing.assert_array_equal(with_effect.measurement.extras["temperature_c"], without.extras["temperature_c"])
    np.testing.assert_array_equal(without.extras["temperature_c"], room_temperature(without.time, 5))


def test_room_temperature_is_seeded_and_slow():
    time = np.arange(0.0, 3600.0, 2.0)
    first, again, other = room_temperature(time, 1), room_temperature(time, 1), room_temperature(time, 2)
    np.testing.assert_array_equal(first, again)
    assert not np.allclose(first, other)
    # a room, not an oven: within 20 +- 2 K, and < 0.01 K/s (the AC cycle: 0.3 K x 2 pi / 150 s)
    assert np.all(np.abs(first - 20.0) < 2.0) and np.abs(np.diff(first) / 2.0).max() < 0.015


def test_simulate_checks_time(prototype):
    with pytest.raises(ValueError, match="non-decreasing"):
        simulate(prototype, SHORT.inputs[:3], time=[0.0, 2.0, 1.0])


def test_thermal_follows_the_given_temperature(prototype):
    effect = dataclasses.replace(make_injector("thermal", 10.0, 1), time_constant=0.0)
    inputs = np.zeros((3, 3))
    hot = simulate(prototype, inputs, effects=[effect], temperature=[20.0, 21.0, 22.0])
    cold = simulate(prototype, inputs, effects=[effect], temperature=[20.0, 20.0, 20.0])
    np.testing.assert_allclose(hot.screw_positions - cold.screw_positions,
                               # alpha x dT added to mm screw positions: round-off (1 ulp of 1 mm = 2e-19 m)
                               np.outer([0.0, 1.0, 2.0], effect.expansion), rtol=1e-12, atol=1e-18)
