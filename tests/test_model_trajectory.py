"""The standard trajectory and travel directions (model/trajectory.py, docs/conventions.md)."""

import numpy as np
import pytest

from flexcal.model.assembly import mechanism_matrices
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import (WORKSPACE, approach_directions, next_direction, standard_trajectory,
                                     travel_directions)


def test_standard_trajectory_layout():
    tr = standard_trajectory()
    assert tr.inputs.shape == (77, 3)
    assert np.bincount(tr.leg).tolist() == [1, 28, 28, 20]
    for k in range(3):
        leg = tr.inputs[tr.leg == k + 1]
        others = np.delete(leg, k, axis=1)
        assert np.all(others == 0.0)  # one actuator at a time
        sweep = leg[:, k]
        n = len(sweep)
        assert sweep[n // 4 - 1] == pytest.approx(tr.amplitudes[k], rel=1e-15)  # turning points sampled exactly
        assert sweep[3 * n // 4 - 1] == pytest.approx(-tr.amplitudes[k], rel=1e-15)  # as above
        assert sweep[-1] == pytest.approx(0.0, abs=1e-18)  # back to zero: round-off of mm inputs (1 ulp = 2e-19 m)


def test_amplitudes_reach_the_workspace_limit_of_the_nominal_linear_model():
    tr = standard_trajectory()
    space = parameter_space()
    gain = mechanism_matrices(space.nominal_full, space).input_gain[0, 3:, 3:]
    for k in range(3):
        reach = np.abs(gain[:, k] * tr.amplitudes[k]) / WORKSPACE
        assert np.max(reach) == pytest.approx(1.0, rel=1e-12)  # the limiting angle touches its bound


def test_other_sizes():
    assert standard_trajectory(n_points=13).n_points == 13
    assert np.bincount(standard_trajectory(n_points=41).leg).tolist() == [1, 16, 16, 8]  # 7:7:5 by largest remainder
    with pytest.raises(ValueError, match="1 \\+ a multiple of 4"):
        standard_trajectory(n_points=76)


def test_travel_directions_remember_the_last_move():
    x = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 0], [1, 0.5, -1]], dtype=float) * 1e-4
    d = travel_directions(x)
    np.testing.assert_array_equal(d[:, 0], [1, 1, 1, -1, -1, -1, -1])  # actuator 1 keeps its last direction
    np.testing.assert_array_equal(d[:, 1], [1, 1, 1, 1, 1, 1, -1])
    np.testing.assert_array_equal(d[:, 2], [1, 1, 1, 1, 1, 1, -1])
    jitter = x.copy()
    jitter[5, 1] -= 1e-12  # below MIN_MOVE: not a move
    np.testing.assert_array_equal(travel_directions(jitter), d)


def test_one_step_rule_walked_point_by_point_is_travel_directions():
    # batched == looped: next_direction walked along random sequences with sub-MIN_MOVE jitter,
    # repeats and reversals gives travel_directions exactly (they are {+1, -1}, no tolerance)
    rng = np.random.default_rng(0)
    for n_points in (1, 2, 7, 50):
        steps = rng.choice([-1e-4, 0.0, 1e-4], size=(n_points, 3)) + rng.uniform(-1e-12, 1e-12, (n_points, 3))
        x = np.cumsum(steps, axis=0)
        direction, walked = np.ones(3), []
        for k in range(n_points):
            direction = next_direction(direction, x[k] - x[k - 1] if k else np.zeros(3))
            walked.append(direction)
        np.testing.assert_array_equal(np.array(walked), travel_directions(x))


def test_approach_directions_are_one_move_from_zero():
    x = np.array([[1e-4, -1e-4, 0.0], [-1e-12, 1e-12, -2e-9], [0.0, 0.0, 0.0]])
    for row, direction in zip(x, approach_directions(x)):
        np.testing.assert_array_equal(direction, travel_directions(np.stack([np.zeros(3), row]))[-1])
    # with min_move 0 every non-zero input is a move: the sign of the input, +1 at exactly 0
    np.testing.assert_array_equal(approach_directions(x, min_move=0.0), np.where(x < 0.0, -1.0, 1.0))
