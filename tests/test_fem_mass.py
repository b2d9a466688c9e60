"""Consistent P2 mass, rigid-body mass and natural modes against closed forms.

Each check can fail: the element mass is compared with the exact integral of products of
barycentric monomials (a lumped mass fails it), the rigid projection with the box's
closed-form mass and inertia, the beam frequencies with Euler-Bernoulli, and a stiff block
on six springs with a dense 6 x 6 solve of the rigid-body equations.
"""

from __future__ import annotations

import itertools
from math import factorial

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp

from flexcal.fem.assembly import assemble_stiffness
from flexcal.fem.coupling import RigidCoupling, coupling_map, rigid_body_modes, select_plane_nodes
from flexcal.fem.eigen import effective_modal_mass, natural_modes
from flexcal.fem.elements import EDGES
from flexcal.fem.mass import assemble_mass, box_inertia, element_mass_scalar, rigid_body_mass
from flexcal.fem.structured import box_tet_mesh
from flexcal.geometry.params import Material

from helpers import well_shaped_p2_tets

NO_POISSON = Material(poisson_ratio=0.0)


def _exact_p2_mass(volume: float, density: float) -> np.ndarray:
    """Scalar P2 mass (10, 10) of a straight tet from int L1^a L2^b L3^c L4^d dV =
    a! b! c! d! 3! V / (a + b + c + d + 3)! (shape functions expanded in barycentric
    monomials: corners 2 L_i^2 - L_i, edges 4 L_i L_j)."""
    def poly(a):  # {exponent tuple: coefficient}
        if a < 4:
            two, one = [0] * 4, [0] * 4
            two[a], one[a] = 2, 1
            return {tuple(two): 2.0, tuple(one): -1.0}
        e = [0] * 4
        e[EDGES[a - 4, 0]] = e[EDGES[a - 4, 1]] = 1
        return {tuple(e): 4.0}

    def integral(exponents):
        num = np.prod([factorial(k) for k in exponents]) * factorial(3)
        return num * volume / factorial(sum(exponents) + 3)

    out = np.zeros((10, 10))
    for a, b in itertools.product(range(10), repeat=2):
        for ea, ca in poly(a).items():
            for eb, cb in poly(b).items():
                out[a, b] += ca * cb * integral(tuple(np.add(ea, eb)))
    return density * out


def test_element_mass_equals_the_exact_integral():
    """Random straight tets: the 14-point mass equals the closed-form integral (round-off;
    the rule is exact for degree 4). HRZ or row-sum lumping differs by O(1)."""
    rng = np.random.default_rng(1)
    coords = well_shaped_p2_tets(rng, 20, curved=False)
    masses = element_mass_scalar(coords, 7850.0)
    for c, m in zip(coords, masses):
        volume = abs(np.linalg.det(c[1:4] - c[0])) / 6.0
        exact = _exact_p2_mass(volume, 7850.0)
        # round-off of a 14-term sum: measured ~1e-16 relative; 1e-12 leaves room
        np.testing.assert_allclose(m, exact, rtol=0, atol=1e-12 * np.abs(exact).max())


def test_rigid_projection_is_the_box_mass_and_inertia():
    """R^T M R (R: the six rigid motions about a point O) of a meshed box is the 6 x 6
    rigid-body mass of ``rigid_body_mass`` with the box's closed-form inertia, exactly
    (the integrand of a rigid field is quadratic)."""
    sides = np.array([1.4, 0.42, 0.2])
    origin = np.array([-0.2, -0.21, -0.1])
    mesh = box_tet_mesh(*sides, 4, 3, 2, origin=tuple(origin))
    material = Material(density=2551.0)
    M = assemble_mass(mesh, material)
    point = np.array([0.1, 0.3, -0.5])
    R = rigid_body_modes(mesh.nodes, origin=point)
    mass = material.density * sides.prod()
    expected = rigid_body_mass(mass, box_inertia(mass, sides), origin + sides / 2, point)
    # round-off on 6e3 DOF: measured 3e-15 of the largest entry
    np.testing.assert_allclose(R.T @ (M @ R), expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    assert M.shape == (3 * len(mesh.nodes),) * 2
    assert abs(M - M.T).max() == 0.0


def _clamped(mesh, stiffness, mass):
    fixed = select_plane_nodes(mesh, ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    T = coupling_map(len(mesh.nodes), mesh.nodes, [RigidCoupling(nodes=fixed, reference_point=np.zeros(3), fixed=True)]).transform
    return (T.T @ stiffness @ T).tocsr(), (T.T @ mass @ T).tocsr()


BETA_L = np.array([1.87510407, 4.69409113, 7.85475744])  # roots of cos x cosh x = -1


@pytest.mark.parametrize("n_length, n_section", [(40, 1), (80, 2)])
def test_clamped_free_beam_frequencies(n_length, n_section):
    """500 x 10 x 10 mm steel cantilever (nu = 0), first three bending frequencies (each
    a pair, y and z) against Euler-Bernoulli f_n = (beta_n L)^2 / (2 pi L^2) sqrt(EI / rho A).

    Tolerance 1 %: the measured errors are -0.03 %, -0.17 %, -0.36 % (40 x 1 cells) and
    -0.03 %, -0.18 %, -0.43 % (80 x 2, one refinement: discretisation changes mode 3 by
    0.07 %); the rest is beam theory leaving out shear and rotary inertia, which lower
    mode n by about (beta_n h)^2 (1 + E / (kappa G)) / 24 = 0.42 % for mode 3 at L/h = 50."""
    L, h = 0.5, 0.01
    mesh = box_tet_mesh(L, h, h, n_length, n_section, n_section, origin=(0.0, -h / 2, -h / 2))
    K, M = _clamped(mesh, assemble_stiffness(mesh, NO_POISSON), assemble_mass(mesh, NO_POISSON))
    result = natural_modes(K, M, 6)
    E, rho = NO_POISSON.youngs_modulus, NO_POISSON.density
    expected = BETA_L**2 / (2 * np.pi * L**2) * np.sqrt(E * h**4 / 12 / (rho * h * h))
    # 1 %: measured -0.03..-0.43 %, mostly beam theory's missing shear/rotary inertia (docstring)
    np.testing.assert_allclose(result.frequencies.reshape(3, 2), np.repeat(expected[:, None], 2, 1), rtol=0.01)
    # M-normalized modes
    np.testing.assert_allclose(result.modes.T @ (M @ result.modes), np.eye(6), atol=1e-9)


def test_stiff_block_on_six_springs_matches_the_dense_rigid_body_solve():
    """A 300 kg block 1400 x 420 x 200 mm, 100 x stiffer than steel, held only by six
    axial springs at its corners: the sparse shift-invert modes of the meshed block equal
    the eigenvalues of the closed-form 6 x 6 problem K6 phi = w^2 M6 phi (dense eigh),
    K6 = sum k_i w_i w_i^T with the spring wrenches w_i = (d_i, r_i x d_i), M6 from
    ``rigid_body_mass``. Tolerance 1e-3: the block's own elasticity lowers the rigid
    frequencies by ~(f / f_elastic)^2 (measured 1e-4); a lumped diagonal mass misses the
    inertia and fails."""
    sides = np.array([1.4, 0.42, 0.2])
    origin = -sides / 2
    mesh = box_tet_mesh(*sides, 4, 2, 1, origin=tuple(origin))
    mass = 300.0
    material = Material(youngs_modulus=206e11, poisson_ratio=0.29, density=mass / sides.prod())
    K = assemble_stiffness(mesh, material).tolil()
    corners = origin + sides * np.array(list(itertools.product([0, 1], repeat=3)))
    directions = np.array([[1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1], [0, 1, 1]], float)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    stiffness = np.array([1e7, 2e7, 1.5e7, 3e7, 1e7, 2.5e7])  # [N/m]
    used = [0, 7, 1, 2, 5, 6]
    K6 = np.zeros((6, 6))
    for corner, d, k in zip(corners[used], directions, stiffness):
        node = int(np.argmin(np.linalg.norm(mesh.nodes - corner, axis=1)))
        dofs = 3 * node + np.arange(3)
        K[np.ix_(dofs, dofs)] = K[np.ix_(dofs, dofs)].toarray() + k * np.outer(d, d)
        w = np.r_[d, np.cross(corner, d)]
        K6 += k * np.outer(w, w)
    M = assemble_mass(mesh, material)
    result = natural_modes(K.tocsr(), M, 6)
    M6 = rigid_body_mass(mass, box_inertia(mass, sides), np.zeros(3), np.zeros(3))
    dense = np.sqrt(scipy.linalg.eigh(K6, M6, eigvals_only=True)) / (2 * np.pi)
    # 1e-3: the block's elasticity lowers the rigid frequencies by ~1e-4 (docstring)
    np.testing.assert_allclose(result.frequencies, dense, rtol=1e-3)
    # effective masses over the six rigid modes add up to the whole mass per direction
    R = rigid_body_modes(mesh.nodes, origin=np.zeros(3))
    totals = effective_modal_mass(M, result.modes, R).sum(axis=0)
    # 1e-3: six rigid modes hold all the translational mass up to the block's elasticity
    np.testing.assert_allclose(totals[:3], mass, rtol=1e-3)


def test_natural_modes_refuses_a_free_body_at_zero_shift():
    mesh = box_tet_mesh(0.1, 0.01, 0.01, 4, 1, 1)
    K, M = assemble_stiffness(mesh, NO_POISSON), assemble_mass(mesh, NO_POISSON)
    with pytest.raises(ValueError, match="free motion"):
        natural_modes(K, M, 3)
    # a negative shift finds the six rigid modes at zero frequency
    free = natural_modes(K, M, 7, shift=-1e3)
    # rigid modes at round-off frequency: < 1e-3 of the first elastic one
    assert np.all(free.frequencies[:6] < 1e-3 * free.frequencies[6])
