"""Guyan (static) reduction of a part's stiffness and consistent mass onto its two end
reference points.

``solve_chain`` (``flexcal.fem.condense``) gives the condensed stiffness
K_c = K_mm - K_mi K_ii^-1 K_im and the static shapes Psi (the unit-motion fields: the
whole part's displacement when one master DOF moves by one unit and the others stay,
interior at rest in equilibrium). Guyan's mass is the consistent mass seen through the
same shapes,

    M_c = Psi^T M Psi                                                    (12 x 12)

exact at zero frequency: the reduced model keeps the part's mass, centre of gravity and
inertia (Psi reproduces every rigid motion) and its static stiffness, and leaves out the
part's own internal modes (a Craig-Bampton basis would add them). For a uniform
Euler-Bernoulli beam the static shapes are the cubic Hermite polynomials, so M_c is the
classic consistent beam mass matrix (tested).

DOF order ux, uy, uz, rx, ry, rz at A then at B, mesh axes (or ``frame``), SI:
stiffness [N/m, N, N m], mass [kg, kg m, kg m^2].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexcal.geometry.params import Material

from .assembly import assemble_stiffness
from .coupling import DEFAULT_PLANE_TOLERANCE
from .condense import ChainSolution, solve_chain
from .mass import assemble_mass

__all__ = ["GuyanPart", "guyan_reduce_part", "reduced_mass", "beam_consistent_mass"]

Plane = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True, kw_only=True, eq=False)
class GuyanPart:
    """stiffness (12, 12) and mass (12, 12) at the reference points A and B (module
    docstring); solution: the ``ChainSolution`` with the unit-motion fields (for stresses
    by linearity); total_mass [kg] of the part (rho V)."""

    stiffness: np.ndarray
    mass: np.ndarray
    solution: ChainSolution
    total_mass: float


def reduced_mass(mass_matrix, unit_motion_fields: np.ndarray) -> np.ndarray:
    """Psi^T M Psi (k, k) [kg, kg m, kg m^2] for the full mass matrix (3 n_nodes, 3 n_nodes)
    and the unit-motion fields (k, n_nodes, 3) [m per unit master DOF]."""
    psi = np.asarray(unit_motion_fields, float).reshape(len(unit_motion_fields), -1).T
    return psi.T @ (mass_matrix @ psi)


def guyan_reduce_part(
    mesh,
    material: Material,
    plane_a: Plane,
    point_a: np.ndarray,
    plane_b: Plane,
    point_b: np.ndarray,
    *,
    frame: np.ndarray | None = None,
    relative_tolerance: float = DEFAULT_PLANE_TOLERANCE,
    method: str = "auto",
) -> GuyanPart:
    """Guyan-reduce a part whose end faces on ``plane_a`` / ``plane_b`` are rigidly coupled
    to ``point_a`` / ``point_b`` [m]: stiffness and consistent mass (12, 12) (module
    docstring). Options as in ``flexcal.fem.condense.solve_chain``."""
    K = assemble_stiffness(mesh, material)
    solution = solve_chain(mesh, material, plane_a, point_a, plane_b, point_b, frame=frame,
                           relative_tolerance=relative_tolerance, method=method, stiffness=K)
    M = assemble_mass(mesh, material)
    M_c = reduced_mass(M, solution.unit_motion_fields)  # fields already in frame axes
    return GuyanPart(stiffness=solution.stiffness, mass=0.5 * (M_c + M_c.T), solution=solution,
                     total_mass=float(M.sum() / 3.0))


def beam_consistent_mass(length: float, area: float, polar: float, density: float) -> np.ndarray:
    """Consistent mass (12, 12) [kg, kg m, kg m^2] of a uniform Euler-Bernoulli beam along
    x: Hermite cubics in bending, linear shapes in tension and torsion, rotary inertia
    left out. length [m], area [m^2], polar second moment of the section [m^4], density
    [kg/m^3]; DOFs ux..rz at the start then at the end. What Guyan's reduction of a
    slender bar gives (tests/test_fem_guyan.py)."""
    m, l = density * area * length, length
    M = np.zeros((12, 12))
    two_node = np.array([[2.0, 1.0], [1.0, 2.0]]) / 6.0
    M[np.ix_([0, 6], [0, 6])] = m * two_node
    M[np.ix_([3, 9], [3, 9])] = density * polar * l * two_node
    bend = m / 420 * np.array([[156, 22 * l, 54, -13 * l], [22 * l, 4 * l * l, 13 * l, -3 * l * l],
                               [54, 13 * l, 156, -22 * l], [-13 * l, -3 * l * l, -22 * l, 4 * l * l]])
    M[np.ix_([1, 5, 7, 11], [1, 5, 7, 11])] = bend
    flip = np.diag([1.0, -1.0, 1.0, -1.0])  # uz, ry: ry = -duz/dx flips the coupling terms
    M[np.ix_([2, 4, 8, 10], [2, 4, 8, 10])] = flip @ bend @ flip
    return M
