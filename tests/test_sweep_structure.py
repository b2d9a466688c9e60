"""The structural columns of a chain sweep (``validation/sweep/chain_structure.py``) on a
slender bar standing in for a chain, against beam closed forms."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from flexcal.fem.assembly import assemble_stiffness
from flexcal.fem.condense import solve_chain
from flexcal.fem.structured import box_tet_mesh
from flexcal.geometry.params import Material
from flexcal.validation.sweep.chain_structure import chain_structure

NO_POISSON = Material(poisson_ratio=0.0)
L, H = 0.2, 0.01  # [m] a 200 x 10 x 10 mm steel bar, L/h = 20
END = L / 10  # [m] the "end blocks" the leaf stress leaves out, next to the coupled faces


class _Bar:
    """A bar as a chain: end blocks of END at each end, the rest one leaf."""

    @staticmethod
    def segments():
        return [("block", 0.0, END), ("leaf1", END, L - END), ("block", L - END, L)]


@pytest.fixture(scope="module")
def figures():
    mesh = box_tet_mesh(L, H, H, 40, 2, 2, origin=(0.0, -H / 2, -H / 2))
    part = SimpleNamespace(end_planes={"A": (np.zeros(3), np.array([-1.0, 0, 0])),
                                       "B": (np.array([L, 0, 0]), np.array([1.0, 0, 0]))},
                           reference_points={"A": np.zeros(3), "B": np.array([L, 0, 0])})
    K = assemble_stiffness(mesh, NO_POISSON)
    solution = solve_chain(mesh, NO_POISSON, part.end_planes["A"], part.reference_points["A"], part.end_planes["B"],
                           part.reference_points["B"], stiffness=K)
    return chain_structure(mesh, NO_POISSON, part, _Bar, solution, K)


E, RHO = NO_POISSON.youngs_modulus, NO_POISSON.density
I = H**4 / 12
PHI = 12 * E * I / (5 / 6 * E / 2 * H * H * L**2)  # Timoshenko's shear parameter of the bar (nu = 0): 0.0072


def test_first_clamped_frequency_is_the_cantilevers(figures):
    """f1 = 1.8751^2 / (2 pi L^2) sqrt(EI / rho A). 1 %: beam theory leaves out shear and
    rotary inertia, ~(beta_1 h)^2 (1 + E / (kappa G)) / 24 = 0.1 % at L/h = 20, and the 40-cell
    P2 mesh is within 0.05 % (tests/test_fem_mass.py); measured -0.16 %."""
    expected = 1.87510407**2 / (2 * np.pi * L**2) * np.sqrt(E * I / (RHO * H * H))
    # 1 %: shear and rotary inertia ~0.1 %, the mesh 0.05 % (docstring); measured -0.16 %
    assert float(figures["first_frequency_clamped_hz"]) == pytest.approx(expected, rel=0.01)


def test_lateral_stiffness_and_sway_load_of_a_guided_beam(figures):
    """End B moved sideways with its turning held, axial free: k = 12 EI / (L^3 (1 + Phi))
    (Timoshenko). 1 %: the rigidly coupled end faces also hold the section's warping, which
    stiffens by a fraction of h / L; measured +0.015 %. The sway load is L k by definition (the
    link model; for this uniform bar it is 12 / pi^2 = 1.21 x Euler's pi^2 EI / L^2, for a strut
    between two short hinges it is the closed form 2 k / L: docs/sweep.md)."""
    expected = 12 * E * I / (L**3 * (1 + PHI))
    # 1 %: the coupled faces' warping restraint, a fraction of h / L (docstring); measured +0.015 %
    np.testing.assert_allclose(figures["lateral_stiffness"], [expected, expected], rtol=0.01)
    assert float(figures["buckling_load_sway"]) == pytest.approx(L * expected, rel=0.01)  # same 1 %: L k


def test_leaf_stress_per_stroke_of_a_guided_beam(figures):
    """Peak bending stress inside the leaf, at END from a coupled face: M = k delta (L/2 - END)
    for a unit delta, sigma = M (h/2) / I. 2 %: P2 tets represent the linear bending stress
    exactly but nodal averaging at the section's corner nodes and the coupled faces' warping
    restraint add ~1 %; measured +0.76 %."""
    k = 12 * E * I / (L**3 * (1 + PHI))
    expected = k * (L / 2 - END) * (H / 2) / I
    # 2 %: nodal averaging and the faces' warping restraint ~1 % (docstring); measured +0.76 %
    np.testing.assert_allclose(figures["stress_per_m_lateral"], [expected, expected], rtol=0.02)
