"""Consistent mass matrix of a P2 tet mesh, and the 6 x 6 mass of a rigid body.

Element mass (same elements, node order and DOF numbering as ``flexcal.fem.elements``):

    M[(a,i),(b,j)] = delta_ij * integral rho N_a N_b dV

On a straight-sided tet ``N_a N_b det J`` has degree 4, so the 14-point rule (degree 5)
integrates it exactly; on a curved tet the integrand has degree 7 and the same rule is an
approximation (as for the curved stiffness). Vectorized over chunks of elements and
summed into the 3 x 3 node blocks of ``flexcal.fem.assembly.node_pattern`` (diagonal
blocks: the mass does not couple components).

``rigid_body_mass``: the 6 x 6 mass of a rigid body at a reference point, DOF order
ux, uy, uz, rx, ry, rz (the master DOFs of ``flexcal.fem.coupling``), for a payload held
by rigid couplings.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from flexcal.geometry.frames import skew
from flexcal.geometry.params import Material

from .assembly import DEFAULT_CHUNK, check_mesh, node_pattern
from .elements import TET_14POINT, InvalidElementError, _physical_gradients, shape_functions

__all__ = ["element_mass_scalar", "assemble_mass", "rigid_body_mass", "box_inertia"]


def element_mass_scalar(coords: np.ndarray, density: float) -> np.ndarray:
    """Scalar element masses m_ab = integral rho N_a N_b dV (n_el, 10, 10) [kg] of P2 tets
    with coords (n_el, 10, 3) [m]; the 30 x 30 element mass is m_ab * delta_ij. 14-point
    rule (exact on straight-sided tets)."""
    coords = np.asarray(coords, float)
    if coords.ndim != 3 or coords.shape[1:] != (10, 3):
        raise ValueError(f"coords has shape {coords.shape}; expected (n_el, 10, 3)")
    _, det = _physical_gradients(coords, TET_14POINT)  # raises InvalidElementError
    N = shape_functions(TET_14POINT.points)  # (q, 10)
    weights = density * det * TET_14POINT.weights  # (e, q)
    return np.einsum("eq,qa,qb->eab", weights, N, N, optimize=True)


def assemble_mass(mesh, material: Material, *, chunk_size: int = DEFAULT_CHUNK) -> sp.csr_matrix:
    """Consistent mass matrix M (3 n_nodes, 3 n_nodes) [kg], CSR with sorted indices and
    the same sparsity pattern as ``assemble_stiffness``. Density from ``material``."""
    nodes, tets = check_mesh(mesh)
    n_nodes = len(nodes)
    indptr, indices, slot = node_pattern(tets, n_nodes)
    scalar = np.zeros(indices.size)
    for start in range(0, len(tets), chunk_size):
        chunk = slice(start, start + chunk_size)
        try:
            m = element_mass_scalar(nodes[tets[chunk]], material.density)
        except InvalidElementError as error:
            raise InvalidElementError(start + error.elements) from None
        np.add.at(scalar, slot[chunk].ravel(), m.ravel())
    blocks = scalar[:, None, None] * np.eye(3)
    M = sp.bsr_matrix((blocks, indices, indptr), shape=(3 * n_nodes, 3 * n_nodes)).tocsr()
    M.eliminate_zeros()
    M.sort_indices()
    return M


def box_inertia(mass: float, sides: np.ndarray) -> np.ndarray:
    """Inertia tensor (3, 3) [kg m^2] about the centre of a homogeneous box of ``mass``
    [kg] and side lengths ``sides`` (3,) [m] along its axes: m (b^2 + c^2) / 12 etc."""
    a2 = np.asarray(sides, float) ** 2
    return mass / 12.0 * np.diag([a2[1] + a2[2], a2[0] + a2[2], a2[0] + a2[1]])


def rigid_body_mass(mass: float, inertia: np.ndarray, centre: np.ndarray, reference_point: np.ndarray) -> np.ndarray:
    """6 x 6 mass matrix [kg, kg m, kg m^2] of a rigid body at ``reference_point`` (3,) [m].

    mass [kg]; inertia (3, 3) [kg m^2] about the centre of gravity ``centre`` (3,) [m].
    DOFs (u, theta) of the reference point; a material point at r from it moves by
    u + theta x r, so with c = centre - reference_point:

        M = [[m I, -m [c]x], [m [c]x, J_c - m [c]x [c]x]]

    (kinetic energy 1/2 v^T M v; parallel-axis theorem in the lower block)."""
    if not mass >= 0:
        raise ValueError(f"mass={mass} kg must be >= 0")
    inertia = np.asarray(inertia, float)
    if inertia.shape != (3, 3) or not np.allclose(inertia, inertia.T, rtol=1e-12, atol=0.0):
        raise ValueError("inertia must be a symmetric (3, 3) tensor [kg m^2] about the centre of gravity")
    c = skew(np.asarray(centre, float) - np.asarray(reference_point, float))
    M = np.zeros((6, 6))
    M[:3, :3] = mass * np.eye(3)
    M[:3, 3:] = -mass * c
    M[3:, :3] = mass * c
    M[3:, 3:] = inertia - mass * c @ c
    return M
