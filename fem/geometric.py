"""Geometric (stress) stiffness of a P2 tet mesh from a prestress field.

For a body carrying the Cauchy stress sigma of a prior linear solve, the second-order
part of the strain energy adds (updated-Lagrangian, small prestrain)

    K_G[(a,i),(b,j)] = delta_ij * integral dN_a/dx_k sigma_kl dN_b/dx_l dV

so that ``(K + lambda K_G) phi = 0`` gives the load factors lambda at which the
prestress, scaled by lambda, buckles the body (``flexcal.fem.eigen.buckling_modes``).
Compression (sigma < 0) makes K_G negative along the buckling shape.

The stress is taken at the points of the 14-point rule (``TET_14POINT``), where
``quadrature_stress`` evaluates it from a displacement field. On a straight-sided tet
the integrand has degree 1 + 1 + 1 = 3 (P2 gradients and stress are linear), so the
rule (degree 5) is exact for a stress field from a P2 solve; on curved tets it is an
approximation, as for the stiffness.

Also ``axial_link_geometric_stiffness``: the 12 x 12 geometric stiffness of an axial
force carried by a two-node link (a reduced chain or segment), for the reduced level.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from flexcal.geometry.params import Material

from .assembly import DEFAULT_CHUNK, check_mesh, node_pattern
from .elements import TET_14POINT, InvalidElementError, _physical_gradients, elasticity_matrix, voigt_strain

__all__ = ["quadrature_stress", "assemble_geometric_stiffness", "axial_link_geometric_stiffness", "STRESS_RULE"]

STRESS_RULE = TET_14POINT
"""The quadrature rule at whose points prestresses are given (n_q = 14)."""

_VOIGT_TO_TENSOR = np.array([[0, 5, 4], [5, 1, 3], [4, 3, 2]])  # xx yy zz yz xz xy -> sigma_kl


def quadrature_stress(mesh, material: Material, u: np.ndarray, *, chunk_size: int = DEFAULT_CHUNK) -> np.ndarray:
    """Cauchy stress (n_tets, 14, 6) [Pa], Voigt order xx, yy, zz, yz, xz, xy, at the
    points of ``STRESS_RULE`` in each element, from displacements u (3 n_nodes,) or
    (n_nodes, 3) [m] (linear elasticity, ``material``)."""
    nodes, tets = check_mesh(mesh)
    u = np.asarray(u, float).reshape(len(nodes), 3)
    D = elasticity_matrix(material)
    out = np.empty((len(tets), STRESS_RULE.weights.size, 6))
    for start in range(0, len(tets), chunk_size):
        chunk = slice(start, start + chunk_size)
        try:
            G, _ = _physical_gradients(nodes[tets[chunk]], STRESS_RULE)  # (e, q, a, i)
        except InvalidElementError as error:
            raise InvalidElementError(start + error.elements) from None
        grad_u = np.einsum("eak,eqai->eqki", u[tets[chunk]], G, optimize=True)  # du_k/dx_i
        out[chunk] = voigt_strain(grad_u) @ D.T
    return out


def assemble_geometric_stiffness(mesh, stress: np.ndarray, *, chunk_size: int = DEFAULT_CHUNK) -> sp.csr_matrix:
    """Geometric stiffness K_G (3 n_nodes, 3 n_nodes) [N/m] of the prestress ``stress``
    (n_tets, 14, 6) [Pa] (Voigt, at the points of ``STRESS_RULE``, as from
    ``quadrature_stress``). Symmetric; same sparsity pattern as the stiffness."""
    nodes, tets = check_mesh(mesh)
    stress = np.asarray(stress, float)
    n_q = STRESS_RULE.weights.size
    if stress.shape != (len(tets), n_q, 6):
        raise ValueError(f"stress has shape {stress.shape}; expected ({len(tets)}, {n_q}, 6) Voigt stresses [Pa] "
                         "at the 14 points of STRESS_RULE (see quadrature_stress)")
    indptr, indices, slot = node_pattern(tets, len(nodes))
    scalar = np.zeros(indices.size)
    for start in range(0, len(tets), chunk_size):
        chunk = slice(start, start + chunk_size)
        try:
            G, det = _physical_gradients(nodes[tets[chunk]], STRESS_RULE)
        except InvalidElementError as error:
            raise InvalidElementError(start + error.elements) from None
        sigma = stress[chunk][..., _VOIGT_TO_TENSOR] * (det * STRESS_RULE.weights)[..., None, None]  # (e, q, 3, 3)
        k = np.einsum("eqak,eqkl,eqbl->eab", G, sigma, G, optimize=True)
        np.add.at(scalar, slot[chunk].ravel(), k.ravel())
    blocks = scalar[:, None, None] * np.eye(3)
    K_G = sp.bsr_matrix((blocks, indices, indptr), shape=(3 * len(nodes),) * 2).tocsr()
    K_G.sort_indices()
    return K_G


def axial_link_geometric_stiffness(length: float | np.ndarray, axial_force: float | np.ndarray) -> np.ndarray:
    """Geometric stiffness (..., 12, 12) [N/m] of an axial force ``axial_force`` [N]
    (tension positive) carried by a straight link of ``length`` [m] along local x between
    two nodes (DOFs ux, uy, uz, rx, ry, rz of the start node then of the end node).

    A lateral offset delta of the end relative to the start tilts the force by delta / L:
    energy N (delta_y^2 + delta_z^2) / (2 L), so K_G = (N / L) [[P, -P], [-P, P]] with
    P = diag(0, 1, 1, 0, 0, 0) (the string stiffness; the distributed-beam terms in the
    rotations are left out: a link between two rigid sections of a chain, whose
    flexibility sits in short hinges, bends little between them)."""
    length = np.asarray(length, float)
    axial_force = np.asarray(axial_force, float)
    if np.any(~(length > 0)):
        raise ValueError(f"link length {length} m must be > 0")
    P = np.diag([0.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    block = np.block([[P, -P], [-P, P]])
    return (axial_force / length)[..., None, None] * block
