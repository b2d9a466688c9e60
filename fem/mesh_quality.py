"""Measures of a tet mesh: shape quality, quadratic-element volume and Jacobians, and
elements through a thin section.

All functions take ``nodes (n_nodes, 3) [m]`` and tets with VTK node order (corners
0-3, then mid-edge nodes 01, 12, 02, 03, 13, 23).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "EDGES",
    "unique_rows",
    "corner_volumes",
    "radius_ratio",
    "min_dihedral_angle",
    "p2_jacobian_determinants",
    "p2_volumes",
    "edge_lengths",
    "tets_crossed_by_line",
]

#: corner pairs of the six edges in VTK quadratic-tet order (mid-nodes 4..9)
EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])


def unique_rows(rows: np.ndarray, n_values: int, **options) -> tuple:
    """``np.unique(rows, axis=0, **options)`` for non-negative int rows (k, 2) or (k, 3)
    with entries < n_values, done on one int64 key per row (much faster)."""
    rows = np.asarray(rows, dtype=np.int64)
    if float(n_values) ** rows.shape[1] >= 2.0**62:  # keys would overflow: the slow way
        return np.unique(rows, axis=0, return_index=True, **options)
    key = rows[:, 0]
    for j in range(1, rows.shape[1]):
        key = key * n_values + rows[:, j]
    out = np.unique(key, return_index=True, **options)
    first = out[1]
    return (rows[first],) + tuple(out[1:])


def corner_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes (n_tets,) [m^3] of the straight tets spanned by corners 0-3."""
    p = nodes[tets[:, :4]]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0


def _faces_area(p: np.ndarray) -> np.ndarray:
    faces = [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]
    return np.stack([0.5 * np.linalg.norm(np.cross(p[:, b] - p[:, a], p[:, c] - p[:, a]), axis=1)
                     for a, b, c in faces], axis=1)


def radius_ratio(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Normalised radius ratio 3 r_in / r_circ (n_tets,) of the corner tets: 1 for a
    regular tet, 0 for a flat one."""
    p = nodes[tets[:, :4]]
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    six_v = np.einsum("ij,ij->i", np.cross(a, b), c)
    r_in = six_v / 2.0 / _faces_area(p).sum(axis=1)
    centre = (np.sum(a * a, 1)[:, None] * np.cross(b, c) + np.sum(b * b, 1)[:, None] * np.cross(c, a)
              + np.sum(c * c, 1)[:, None] * np.cross(a, b)) / (2.0 * six_v[:, None])
    return 3.0 * r_in / np.linalg.norm(centre, axis=1)


def min_dihedral_angle(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Smallest dihedral angle (n_tets,) [deg] of each corner tet (70.53 deg when regular)."""
    p = nodes[tets[:, :4]]
    faces = [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]
    normals = np.stack([np.cross(p[:, b] - p[:, a], p[:, c] - p[:, a]) for a, b, c in faces], axis=1)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    angles = [np.pi - np.arccos(np.clip(np.einsum("ij,ij->i", normals[:, i], normals[:, j]), -1, 1))
              for i in range(4) for j in range(i + 1, 4)]
    return np.degrees(np.min(angles, axis=0))


def edge_lengths(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Corner-to-corner edge lengths (n_tets, 6) [m]."""
    p = nodes[tets[:, :4]]
    return np.linalg.norm(p[:, EDGES[:, 1]] - p[:, EDGES[:, 0]], axis=2)


def _p2_gradients(bary: np.ndarray) -> np.ndarray:
    """Gradients (n_points, 10, 3) of the P2 shape functions w.r.t. the reference
    coordinates (xi, eta, zeta) = (l1, l2, l3), at barycentric points (n_points, 4)."""
    dl = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    out = np.empty((len(bary), 10, 3))
    for i in range(4):
        out[:, i] = (4.0 * bary[:, i] - 1.0)[:, None] * dl[i]
    for m, (i, j) in enumerate(EDGES):
        out[:, 4 + m] = 4.0 * (bary[:, i, None] * dl[j] + bary[:, j, None] * dl[i])
    return out


def p2_jacobian_determinants(nodes: np.ndarray, tets: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """det J (n_tets, n_points) of the quadratic map at barycentric points (n_points, 4)."""
    grads = _p2_gradients(np.asarray(bary, float))  # (n_points, 10, 3)
    x = nodes[tets].transpose(0, 2, 1)  # (n_tets, 3, 10)
    jac = np.matmul(x[:, None], grads[None])  # J_ik = sum_a x_ai dN_a/dxi_k
    return np.linalg.det(jac)


# Keast's 5-point rule, exact for cubics (det J of a P2 tet is cubic); weights sum to 1
_RULE_POINTS = np.array([[0.25, 0.25, 0.25, 0.25]] + [np.roll([0.5, 1 / 6, 1 / 6, 1 / 6], k) for k in range(4)])
_RULE_WEIGHTS = np.array([-0.8] + [0.45] * 4)


def p2_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Volumes (n_tets,) [m^3] of the curved quadratic tets (exact: cubic integrand)."""
    det = p2_jacobian_determinants(nodes, tets, _RULE_POINTS)
    return det @ _RULE_WEIGHTS / 6.0


def tets_crossed_by_line(nodes: np.ndarray, tets: np.ndarray, origin: np.ndarray, direction: np.ndarray,
                         min_length: float = 0.0) -> np.ndarray:
    """Indices of the corner tets that the infinite line origin + s * direction passes
    through over a length > min_length [m] (touching an edge or a face does not count)."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    o = np.asarray(origin, float)
    p = nodes[tets[:, :4]]
    # quick rejection: distance of the line from the tet's bounding sphere
    centre = p.mean(axis=1)
    radius = np.linalg.norm(p - centre[:, None], axis=2).max(axis=1)
    rel = centre - o
    off_axis = np.linalg.norm(rel - np.outer(rel @ d, d), axis=1)
    cand = np.nonzero(off_axis <= radius)[0]
    if len(cand) == 0:
        return cand
    q = p[cand]
    t = np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]], axis=2)  # columns
    inv = np.linalg.inv(t)
    lam0 = np.einsum("nij,nj->ni", inv, o - q[:, 0])
    dlam = np.einsum("nij,j->ni", inv, d)
    lam0 = np.concatenate([1 - lam0.sum(1, keepdims=True), lam0], axis=1)
    dlam = np.concatenate([-dlam.sum(1, keepdims=True), dlam], axis=1)
    # lam0 + s * dlam >= 0 for all four: intersect the half-lines
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = -lam0 / dlam
    lo = np.where(dlam > 0, bound, -np.inf).max(axis=1)
    hi = np.where(dlam < 0, bound, np.inf).min(axis=1)
    parallel_outside = ((np.abs(dlam) == 0) & (lam0 < 0)).any(axis=1)
    ok = (hi - lo > max(min_length, 1e-12 * float(np.max(radius)))) & ~parallel_outside
    return cand[ok]
