"""Inverse (model/inverse.py): round trips, the analytic Jacobian, the dead band error."""

import numpy as np
import pytest

from flexcal.model.assembly import mechanism_matrices
from flexcal.model.forward import forward, solve_matrices
from flexcal.model.inverse import NotInvertibleError, forward_jacobian, inverse
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import standard_trajectory

SPACE = parameter_space()
TRAJECTORY = standard_trajectory()


def test_nominal_round_trip_on_the_standard_trajectory():
    target = forward(SPACE.nominal_full, TRAJECTORY.inputs).angles[0]
    result = inverse(target)
    # acceptance: <= 1e-9 m and 1e-9 rad; the solver's own tolerance is 1e-12 rad
    np.testing.assert_allclose(result.inputs, TRAJECTORY.inputs, rtol=0, atol=1e-9)
    back = forward(SPACE.nominal_full, result.inputs, result.directions).angles[0]
    np.testing.assert_allclose(back, target, rtol=0, atol=1e-9)  # the acceptance above (measured 4e-13)
    # the solver's own tolerance (comment above)
    assert np.max(np.abs(result.residual)) <= 1e-12 and result.directions_consistent


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_round_trip_with_all_error_sources(seed):
    rng = np.random.default_rng(seed)
    values = SPACE.from_unit(rng.random(45))
    values[SPACE.index("D1.mu")] = min(values[SPACE.index("D1.mu")], 0.95)  # keep a gain in the gap
    target = forward(values, TRAJECTORY.inputs).angles[0]
    result = inverse(target, TRAJECTORY.directions, space_values=values)
    # acceptance of docs/model.md, as above
    np.testing.assert_allclose(result.inputs, TRAJECTORY.inputs, rtol=0, atol=1e-9)
    back = forward(values, result.inputs, TRAJECTORY.directions).angles[0]
    np.testing.assert_allclose(back, target, rtol=0, atol=1e-9)  # as above


def test_forward_of_inverse_hits_arbitrary_targets():
    values = SPACE.build_values({"D1.CL": 0.2e-3, "D1.mu": 0.85, "D3.CL": 0.1e-3, "D3.mu": 0.9, "L2.d": 1e-3,
                                 "L2.phi": 2.0, "D2.x0": 0.3e-3})
    grid = np.array([[0.0, 0.0, 0.0], [8e-4, -4e-3, 2e-3], [-9e-4, 4.5e-3, -2.5e-3], [3e-4, 1e-3, 0.0]])
    result = inverse(grid, space_values=values)
    back = forward(values, result.inputs, result.directions).angles[0]
    np.testing.assert_allclose(back, grid, rtol=0, atol=1e-9)  # acceptance of docs/model.md, as above


def test_analytic_jacobian_matches_finite_differences():
    values = SPACE.from_unit(np.random.default_rng(9).random(45))
    m = mechanism_matrices(values, SPACE)
    x, d = TRAJECTORY.inputs[::5], TRAJECTORY.directions[::5]
    options = dict(tol=1e-15, max_iter=200)
    jac = forward_jacobian(m, solve_matrices(m, x, d, **options), d)
    h = 1e-8  # [m]: central differences, truncation ~h^2 * 1/L_d ~ 1e-15, rounding ~1e-16/h
    fd = np.zeros_like(jac)
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        plus = solve_matrices(m, x + step, d, **options)["pose"][0, :, 3:]
        minus = solve_matrices(m, x - step, d, **options)["pose"][0, :, 3:]
        fd[:, :, k] = (plus - minus) / (2 * h)
    # points sitting within h of a clearance kink have one-sided derivatives; skip those
    smooth = np.max(np.abs(jac - fd), axis=(1, 2)) < 1e-3 * np.abs(jac).max()
    assert smooth.mean() > 0.9  # at most 1 of the 16 points may sit within h of a kink (measured: none)
    np.testing.assert_allclose(jac[smooth], fd[smooth], rtol=0, atol=1e-7 * np.abs(jac).max())  # ~1e-16/h


def test_zero_gain_in_the_gap_is_reported_with_point_and_chain():
    # D3 carries ~+100 N tension at the design pose: with CL = 0.5 mm and mu = 1 its nut
    # floats in the gap and follows the screw without moving the chain
    values = SPACE.build_values({"D3.CL": 0.5e-3, "D3.mu": 1.0})
    start = forward(values, np.zeros((2, 3)), np.ones((2, 3)))
    assert start.chain_states[0, 0, 2] == 1  # "gap"
    with pytest.raises(NotInvertibleError) as info:
        inverse(start.angles[0] + np.array([[0, 0, 0], [1e-6, 0, 0]]), np.ones((2, 3)), space_values=values)
    assert "D3" in str(info.value) and info.value.chains == ("D3",) and info.value.point in (0, 1)
    assert f"point {info.value.point}" in str(info.value)
