"""Clearance (Eq. 6-7, model/clearance.py): the reading on a worked example, the exact coupled
solve against the fixed-point conditions, held faces, enumeration fallback."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flexcal.model import clearance
from flexcal.model.assembly import mechanism_matrices
from flexcal.model.parameters import DRIVING, parameter_space

SPACE = parameter_space()


def box(directions, limit):
    reach = directions * limit
    return np.minimum(reach, 0.0), np.maximum(reach, 0.0)


@pytest.mark.parametrize("load, direction, expected_mm", [
    (800.0, +1, 0.5),  # tension after a forward move: fx = +0.8 mm, mu fx = 0.64 mm > CL -> far flank
    (800.0, -1, 0.0),  # tension after a backward move: the load presses the driving flank -> engaged
    (-300.0, +1, 0.0),  # compression after a forward move -> engaged
    (-300.0, -1, -0.24),  # compression after a backward move: fx = 0.3 mm, C = -mu fx = -0.24 mm (gap)
])
def test_single_chain_worked_example(load, direction, expected_mm):
    s, mu, limit = 1e6, 0.8, 0.5e-3  # nut stiffness [N/m], hysteresis [-], clearance [m]
    a = np.full((1, 3, 1), mu * load / s)  # three uncoupled copies
    lo, hi = box(np.full((1, 3, 1), float(direction)), limit)
    c, status = clearance.solve_clearance(a, np.zeros((1, 3, 3)), lo, hi)
    np.testing.assert_allclose(c, expected_mm * 1e-3, rtol=1e-15, atol=0)  # exact arithmetic


def coupled_instances(n_candidates, seed):
    values = SPACE.from_unit(np.random.default_rng(seed).random((n_candidates, 45)))
    m = mechanism_matrices(values, SPACE)
    coupling = clearance.clearance_coupling(m.coupling[:, DRIVING, DRIVING], m.nut_stiffness, m.mu)
    return m, coupling


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31))
def test_coupled_solution_satisfies_eq7_for_all_chains(seed):
    m, coupling = coupled_instances(6, seed % 1000)
    rng = np.random.default_rng(seed)
    n_p = 40
    a = rng.normal(0.0, 0.6e-3, (6, 3, n_p))  # release targets around the clearance size
    directions = rng.choice([-1.0, 1.0], (1, 3, n_p))
    lo, hi = box(directions, m.clearance[:, :, None])
    c, status = clearance.solve_clearance(a, coupling, lo, hi)
    z = a + coupling @ c
    # the fixed point C = clip(a + B C, lo, hi); 1e-13 m relative to |a| is the solver's KKT slack
    np.testing.assert_allclose(c, np.clip(z, lo, hi), rtol=0, atol=1e-13 + 1e-12 * np.abs(a).max())
    held = clearance.FixedFaces(status, coupling, lo, hi)(a)
    np.testing.assert_allclose(held, c, rtol=0, atol=1e-15)  # the same face, the same linear solve


def test_enumeration_fallback_finds_the_same_solution():
    m, coupling = coupled_instances(4, 11)
    rng = np.random.default_rng(2)
    a = rng.normal(0.0, 0.6e-3, (4, 3, 25))
    lo, hi = box(rng.choice([-1.0, 1.0], (1, 3, 25)), m.clearance[:, :, None])
    exact, _ = clearance.solve_clearance(a, coupling, lo, hi)
    flat = lambda x: np.moveaxis(x, 1, 2).reshape(-1, 3)  # noqa: E731
    enumerated, violation = clearance._enumerate(flat(a), np.repeat(coupling, 25, axis=0), flat(lo), flat(hi))
    assert np.all(violation <= 0)
    # the solution of the box QP is unique (M positive definite): both routes give it
    np.testing.assert_allclose(enumerated, flat(exact), rtol=0, atol=1e-13 + 1e-12 * np.abs(a).max())


def test_the_qp_matrix_is_positive_definite():
    # the uniqueness argument of the module docstring, checked on random candidates
    m, coupling = coupled_instances(50, 3)
    scale = m.mu / m.nut_stiffness
    matrix = (np.eye(3) - coupling) / scale[:, :, None]  # diag(s/mu)(I - B)
    # symmetric up to round-off of the scaling
    np.testing.assert_allclose(matrix, np.swapaxes(matrix, 1, 2), rtol=1e-12, atol=0)
    assert np.all(np.linalg.eigvalsh(0.5 * (matrix + np.swapaxes(matrix, 1, 2))) > 0)
