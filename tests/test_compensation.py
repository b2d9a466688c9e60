"""Closed-loop compensation: the pure loop (calibration.compensation), the target set, the
return-offset removal, and the model-side pieces of validation.compensate (no prototype)."""

import numpy as np
import pytest

from flexcal.calibration.compensation import (LoopSettings, closed_loop, correction_step, iterate,
                                              within_tolerance)
from flexcal.model.forward import forward, ideal_angles
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import WORKSPACE, standard_trajectory
from flexcal.validation.runs.compensate import (calibrated_inputs, model_input_jacobian, model_states, model_zero_angles, return_offsets, small_deflection_inputs)
from flexcal.validation.measurements import Measurement
from flexcal.validation.prototype.scenario import load_scenario
from flexcal.validation.runs.targets import default_targets, read_targets, write_targets
from flexcal.validation.runs.verify import remove_return_offsets

GAIN = np.array([[-1.0, -1.0, -1.6], [-3.2, -3.2, 0.1], [-0.8, 0.8, 0.0]])  # [rad/m], the mount's order


def toy_plant(x):
    """A smooth nonlinear 'mechanism': theta = G x + quadratic coupling [rad], x [m]."""
    return x @ GAIN.T + 50.0 * np.stack([x[:, 0] * x[:, 1], x[:, 1] ** 2, x[:, 2] * x[:, 0]], axis=1)


def toy_model_jacobian(x):
    """The 'calibrated model' Jacobian: the linear part only, 10 % off in gain (a wrong model)."""
    return np.broadcast_to(1.1 * GAIN, (len(x), 3, 3))


def toy_targets(n=12, seed=0):
    rng = np.random.default_rng(seed)
    return toy_plant(rng.uniform(-1e-3, 1e-3, (n, 3)))


def test_loop_converges_to_tolerance_with_an_approximate_jacobian():
    targets = toy_targets()
    first = np.linalg.solve(GAIN, targets.T).T  # the linear model's inverse: misses the quadratic part
    settings = LoopSettings(tolerance=1e-10, max_rounds=30)
    result = iterate(targets, first, toy_plant, toy_model_jacobian, settings)
    assert result.converged
    assert np.all(np.abs(result.final.error) <= settings.tolerance)
    assert np.max(np.abs(result.first.error)) > 100 * settings.tolerance  # there was something to correct
    # contraction |1 - 1/1.1| ~ 0.09 per round plus the quadratic term: errors of ~1e-5 rad
    # reach 1e-10 in about 5-6 rounds; 12 allows for the nonlinearity without hiding a stall
    assert 1 <= result.n_corrections <= 12
    # the max error decreases every round (a contraction, not luck)
    maxima = [np.max(np.abs(r.error)) for r in result.rounds]
    assert all(b < a for a, b in zip(maxima, maxima[1:]))


def test_loop_stops_after_max_rounds_when_noise_exceeds_the_tolerance():
    targets = toy_targets(5)
    rng = np.random.default_rng(1)

    def noisy(x):  # readings 10x noisier than the tolerance can never all pass
        return toy_plant(x) + rng.normal(scale=1e-8, size=x.shape)

    settings = LoopSettings(tolerance=1e-9, max_rounds=3)
    result = iterate(targets, np.zeros((5, 3)), noisy, toy_model_jacobian, settings)
    assert not result.converged
    assert len(result.rounds) == 4 and result.n_corrections == 3


def test_only_points_outside_the_tolerance_are_corrected():
    x_true = np.random.default_rng(2).uniform(-1e-3, 1e-3, (4, 3))
    targets = toy_plant(x_true)
    first = np.linalg.solve(GAIN, targets.T).T
    first[0] = x_true[0]  # point 0 starts exactly on target
    result = iterate(targets, first, toy_plant, toy_model_jacobian, LoopSettings(tolerance=1e-12, max_rounds=2))
    assert result.rounds[0].corrected.all()
    assert not result.rounds[1].corrected[0] and result.rounds[1].corrected[1:].all()
    np.testing.assert_array_equal(result.rounds[1].inputs[0], first[0])


def test_correction_step_is_the_newton_step_and_refuses_a_singular_jacobian():
    jac = np.broadcast_to(GAIN, (3, 3, 3)).copy()
    error = np.array([[1e-6, 0, 0], [0, 2e-6, 0], [0, 0, -1e-6]])
    step = correction_step(jac, error)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", jac, step), -error, rtol=0, atol=1e-18)  # rounding of 1e-6
    jac[1] = 0.0
    with pytest.raises(ValueError, match="singular at point 1"):
        correction_step(jac, error)


def test_closed_loop_runs_the_fig9_steps_in_order():
    calls = []
    targets = toy_targets(3)

    def identify():
        calls.append("identify")
        return "model"

    def inverse(model, t):
        calls.append(f"inverse:{model}")
        return np.linalg.solve(GAIN, t.T).T

    model, result = closed_loop(targets, identify=identify, inverse=inverse, drive_and_measure=toy_plant,
                                input_jacobian=lambda m, x: toy_model_jacobian(x),
                                settings=LoopSettings(tolerance=1e-11))
    assert model == "model" and calls == ["identify", "inverse:model"]
    assert result.converged


@pytest.mark.parametrize("kwargs", [dict(tolerance=0.0), dict(max_rounds=-1), dict(gain=0.0), dict(gain=1.5)])
def test_loop_settings_are_checked(kwargs):
    with pytest.raises(ValueError):
        LoopSettings(**kwargs)


def test_within_tolerance_is_per_point_all_angles():
    error = np.array([[1e-7, -1e-7, 0.0], [1e-7, 2e-6, 0.0]])
    np.testing.assert_array_equal(within_tolerance(error, 1e-6), [True, False])


# --- targets ---------------------------------------------------------------------------------

def test_default_targets_spread_over_the_workspace_off_the_calibration_axes():
    targets = default_targets()
    assert targets.shape == (30, 3)
    np.testing.assert_array_equal(targets, default_targets())  # deterministic
    # targets are drawn within +-80 % of the workspace; 1e-18 for rounding
    assert np.all(np.abs(targets) <= 0.8 * WORKSPACE + 1e-18)
    # spread: every angle covers most of its +-80 % range, both signs
    assert np.all(targets.max(axis=0) > 0.6 * WORKSPACE) and np.all(targets.min(axis=0) < -0.6 * WORKSPACE)
    # validation points, not sampling points: the calibration sweeps move one actuator at a
    # time, so their inputs have one non-zero entry; the targets' inputs never do
    inputs = small_deflection_inputs(targets, parameter_space())
    # 1 um: far below the targets' mm inputs, far above round-off of a zero entry
    assert np.all(np.sum(np.abs(inputs) > 1e-6, axis=1) >= 2)


def test_targets_file_round_trip_and_errors(tmp_path):
    targets = default_targets(5)
    path = tmp_path / "t.csv"
    write_targets(path, targets)
    np.testing.assert_allclose(read_targets(path), targets, rtol=0, atol=1e-12)  # 6 decimals of urad
    (tmp_path / "bad.csv").write_text("theta_x_urad,theta_y_urad\n1,2\n")
    with pytest.raises(ValueError, match="theta_z_urad"):
        read_targets(tmp_path / "bad.csv")
    (tmp_path / "far.csv").write_text("theta_x_urad,theta_y_urad,theta_z_urad\n0,0,0\n2000,0,0\n")
    with pytest.raises(ValueError, match="target 2"):
        read_targets(tmp_path / "far.csv")
    (tmp_path / "nan.csv").write_text("theta_x_urad,theta_y_urad,theta_z_urad\n0,x,0\n")
    with pytest.raises(ValueError, match="row 2"):
        read_targets(tmp_path / "nan.csv")
    with pytest.raises(FileNotFoundError):
        read_targets(tmp_path / "missing.csv")


# --- return-offset removal (paper Sec. 4.2) ---------------------------------------------------

def _curve(angles, dwell=2.0):
    trajectory = standard_trajectory()
    n = trajectory.n_points
    return Measurement(point=np.arange(1, n + 1), time=np.arange(n) * dwell, leg=trajectory.leg,
                       inputs=trajectory.inputs, angles=angles)


def test_return_offset_removal_recovers_an_injected_linear_drift():
    trajectory = standard_trajectory()
    clean = ideal_angles(trajectory.inputs)  # memoryless: each leg returns exactly to its start
    curve = _curve(clean)
    rate = np.array([-10.0, -11.0, 25.0]) * 1e-6 / curve.time[-1]  # the paper's return offsets over one run
    drifted = _curve(clean + rate * curve.time[:, None])
    recovered = remove_return_offsets(drifted)
    # exact up to rounding of ~1e-3 rad angles (1e-19) summed over three legs
    np.testing.assert_allclose(recovered, clean, rtol=0, atol=1e-15)
    assert np.max(np.abs(drifted.angles - clean)) > 20e-6  # the drift was there
    offsets = return_offsets(drifted)  # each leg's share: rate x its duration
    assert sorted(offsets) == [1, 2, 3]
    for leg, offset in offsets.items():
        index = np.flatnonzero(drifted.leg == leg)
        duration = drifted.time[index[-1]] - drifted.time[index[0] - 1]
        # rate x duration vs differences of ~1e-3 rad angles: round-off, as above
        np.testing.assert_allclose(offset, rate * duration, rtol=0, atol=1e-15)


def test_return_offset_removal_leaves_a_drift_free_curve_alone():
    clean = ideal_angles(standard_trajectory().inputs)
    # a clean curve: offsets are differences of equal angles, round-off of ~1e-3 rad (2e-19)
    np.testing.assert_allclose(remove_return_offsets(_curve(clean)), clean, rtol=0, atol=1e-18)


# --- the calibrated model's side -------------------------------------------------------------

@pytest.fixture(scope="module")
def table1():
    scenario = load_scenario("table1")
    return scenario.space, scenario.values


def test_small_deflection_inputs_reach_the_targets_on_the_ideal_model():
    space = parameter_space()
    targets = default_targets(8)
    inputs = small_deflection_inputs(targets, space)
    relative = ideal_angles(inputs, space) - ideal_angles(np.zeros((1, 3)), space)
    np.testing.assert_allclose(relative, targets, rtol=0, atol=1e-15)  # linear model: exact to rounding


def test_calibrated_inputs_drive_the_model_exactly_to_target(table1):
    space, values = table1
    targets = default_targets(12)
    inputs = calibrated_inputs(values, targets, space)
    reached = np.stack([forward(values, x[None], space=space).angles[0, 0] for x in inputs])  # each from zero
    # the inverse's Newton tolerance is 1e-12 rad
    np.testing.assert_allclose(reached - model_zero_angles(values, space), targets, rtol=0, atol=2e-12)
    classes, release = model_states(values, inputs, space)
    assert set(classes) <= {"S1", "S2", "S3"} and release.shape == (12, 3)


def test_model_input_jacobian_matches_finite_differences(table1):
    space, values = table1
    inputs = calibrated_inputs(values, default_targets(4), space)
    jac = model_input_jacobian(values, inputs, space)
    h = 1e-8  # [m]: 1e-8 of the ~1 mm inputs, well above the model's 1e-13 m fixed-point tolerance
    for j in range(3):
        step = np.zeros(3)
        step[j] = h
        plus = np.stack([forward(values, (x + step)[None], space=space).angles[0, 0] for x in inputs])
        minus = np.stack([forward(values, (x - step)[None], space=space).angles[0, 0] for x in inputs])
        # central difference: O(h^2) truncation, ~1e-13 rad rounding / 2h -> ~1e-5 relative
        np.testing.assert_allclose(jac[:, :, j], (plus - minus) / (2 * h), rtol=1e-4, atol=1e-4)


def test_backtracking_tames_a_jacobian_three_times_too_small():
    # the mechanism is 3x stiffer-to-rotate than the model says on one side of a kink
    # (a drive chain leaving its clearance): a full Newton step on the model's Jacobian
    # overshoots by 2x per round and diverges (error -> -2 error); the backtracking halves
    # the step until it contracts (1 - 3 / 2 = -0.5 per round) and reaches the tolerance
    from flexcal.calibration.compensation import LoopSettings, iterate

    model_jacobian = np.diag([2.0e-3, 1.0e-3, 1.5e-3])  # [rad/m]

    def drive(x):
        scale = np.where(x[:, :1] > 0, 3.0, 1.0)
        return scale * (x @ model_jacobian.T)

    targets = np.array([[3e-6, 0.0, 0.0]])
    first = np.array([[0.2e-3, 0.0, 0.0]])  # short of the solution x = 0.5 mm (3 * 2e-3 * x = 3e-6)
    result = iterate(targets, first, drive, lambda x: np.broadcast_to(model_jacobian, (len(x), 3, 3)),
                     LoopSettings(tolerance=1e-9, max_rounds=40))
    assert result.converged
    sizes = [float(np.max(np.abs(r.error))) for r in result.rounds]
    # one overshoot (2x, the first full step) before the retreat, never more
    assert sizes[-1] <= 1e-9 and max(sizes) <= 2.01 * sizes[0]


def test_without_backtracking_that_case_never_converges():
    # the control for the test above: the plain Newton update on the same kink overshoots
    # and ends in a 2-cycle at 3.3x the starting error
    model_jacobian = np.diag([2.0e-3, 1.0e-3, 1.5e-3])
    x = np.array([0.2e-3, 0.0, 0.0])
    errors = []
    for _ in range(10):
        measured = (3.0 if x[0] > 0 else 1.0) * model_jacobian @ x
        error = measured - np.array([3e-6, 0.0, 0.0])
        errors.append(abs(error[0]))
        x = x - np.linalg.solve(model_jacobian, error)
    assert min(errors[3:]) > 3 * errors[0]


def test_broyden_update_reproduces_the_measured_change():
    from flexcal.calibration.compensation import broyden_update

    rng = np.random.default_rng(0)
    jacobian = rng.normal(size=(4, 3, 3)) * 1e-3
    dx = rng.normal(size=(4, 3)) * 1e-4
    dtheta = rng.normal(size=(4, 3)) * 1e-6
    dx[3] = 0.0  # a point that did not move keeps its Jacobian
    updated = broyden_update(jacobian, dx, dtheta, min_change=1e-9)
    # the secant condition, to rounding (values ~1e-7, products of ~1e-3 and ~1e-4)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", updated[:3], dx[:3]), dtheta[:3], rtol=0, atol=1e-18)
    np.testing.assert_array_equal(updated[3], jacobian[3])
    # a change below min_change (noise) leaves the Jacobian alone
    np.testing.assert_array_equal(broyden_update(jacobian, dx, dtheta, min_change=1.0), jacobian)


def test_secant_updates_speed_up_a_sluggish_point():
    # a point in a drive's clearance answers only 0.2 of what the model predicts: the
    # relaxed Newton contracts by 0.8 per round (14 rounds to 1e-2 of the start); with the
    # Broyden update the second correction already uses the measured slope
    from flexcal.calibration.compensation import LoopSettings, iterate

    model_jacobian = np.diag([2.0e-3, 1.0e-3, 1.5e-3])
    targets = np.array([[4e-6, -2e-6, 1e-6]])
    result = iterate(targets, np.zeros((1, 3)), lambda x: 0.2 * x @ model_jacobian.T,
                     lambda x: np.broadcast_to(model_jacobian, (len(x), 3, 3)),
                     LoopSettings(tolerance=1e-9, max_rounds=10))
    assert result.converged and result.n_corrections <= 3
