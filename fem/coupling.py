"""Constraints by elimination: rigid couplings (RBE2), other kinematic couplings, and
prescribed DOFs.

A rigid coupling ties a set of slave nodes (an end face) to a 6-DOF reference point
(master) at x_m: ``u_s = u_m + theta_m x (x_s - x_m)`` for every slave node s. The slave
DOFs are eliminated through a transformation ``u_full = T @ u_reduced``; the reduced
system is ``T^T K T u_r = T^T f``. No penalty, so the coupling is exact and adds no
conditioning problem. A clamp is a coupling whose reference point is fixed: its master
DOFs are dropped (all slave DOFs become zero).

Any kinematic coupling is the same elimination: its slaves follow ``u_s = Phi(x_s) q`` for
its n_master DOFs q, ``Phi`` given by the coupling's ``slave_modes`` ((n_s, 3, n_master));
the rigid one's is ``[I, -[x_s - x_m]x]`` (``flexcal.fem.interface`` has polynomial ones).
Its ``master_parity(axis)`` says how each master DOF's field behaves under the mirror
y -> -y (axis 1) or z -> -z (axis 2), for condensations on a mirror part.

Reduced DOF layout: first the 3 DOFs of every node that is not a slave, in node order;
then the master DOFs of every free coupling in coupling order (6: ux, uy, uz, rx, ry, rz
for a rigid one).

Planes are ``(point (3,), normal (3,))`` [m]; face nodes are the nodes within
``relative_tolerance * mesh_size`` of the plane, ``mesh_size`` = median corner-edge
length of the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from flexcal.geometry.frames import skew

__all__ = [
    "DEFAULT_PLANE_TOLERANCE",
    "MIRROR_PARITY",
    "RigidCoupling",
    "CouplingMap",
    "mesh_size",
    "select_plane_nodes",
    "coupling_map",
    "rigid_body_modes",
    "eliminate_dofs",
]

DEFAULT_PLANE_TOLERANCE = 1e-3
"""Face-node tolerance as a fraction of the median corner-edge length. Structured and
CAD-projected meshes put face nodes on the plane to round-off (1e-16 relative); the
nearest off-plane node is a mid-edge node at ~ 1/2 of an edge length. 1e-3 sits far from
both; raise it (up to ~ 0.1) for a mesher that leaves face nodes slightly off the plane."""


# Parity of each rigid master DOF (ux, uy, uz, rx, ry, rz) under the mirror y -> -y (axis 1)
# and z -> -z (axis 2): +1 if a unit motion of it is mirror-symmetric (u(Mx) = M u(x)), -1 if
# antisymmetric (u(Mx) = -M u(x)); rotations are pseudovectors, r -> -M r.
MIRROR_PARITY = {1: np.array([1, -1, 1, -1, 1, -1]), 2: np.array([1, 1, -1, -1, -1, 1])}


@dataclass(frozen=True, kw_only=True, eq=False)
class RigidCoupling:
    """Slave nodes (n_s,) int rigidly tied to a reference point (3,) [m];
    ``fixed=True`` clamps the reference point (a built-in end)."""

    nodes: np.ndarray
    reference_point: np.ndarray
    fixed: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "nodes", np.unique(np.asarray(self.nodes, dtype=np.int64)))
        object.__setattr__(self, "reference_point", np.asarray(self.reference_point, float).reshape(3))
        if self.nodes.size == 0:
            raise ValueError("a rigid coupling needs at least one slave node")

    def slave_modes(self, points: np.ndarray) -> np.ndarray:
        """(n, 3, 6) [m per m, m per rad]: the displacement of ``points`` (n, 3) [m] per unit
        master DOF, ``u = u_m + theta_m x (x - x_m) = u_m - [x - x_m]x theta_m``."""
        points = np.asarray(points, float).reshape(-1, 3)
        modes = np.zeros((len(points), 3, 6))
        modes[:, :, :3] = np.eye(3)
        modes[:, :, 3:] = -skew(points - self.reference_point)
        return modes

    def master_parity(self, axis: int) -> np.ndarray:
        """(6,) +1 / -1: ``MIRROR_PARITY[axis]`` (the reference point on the mirror plane)."""
        return MIRROR_PARITY[axis]


@dataclass(frozen=True, kw_only=True, eq=False)
class CouplingMap:
    """Result of ``coupling_map``.

    transform: T (3 n_nodes, n_reduced) CSR, u_full = T @ u_reduced.
    master_dofs: for each coupling, the (n_master,) indices of its master DOFs in the
    reduced vector (6 for a rigid one), or ``None`` for a fixed reference point.
    free_node_dofs: (n_reduced_nodal,) full DOF index of each leading reduced DOF."""

    transform: sp.csr_matrix
    master_dofs: tuple[np.ndarray | None, ...]
    free_node_dofs: np.ndarray

    @property
    def n_reduced(self) -> int:
        return self.transform.shape[1]


def mesh_size(mesh) -> float:
    """Median corner-edge length [m] of the mesh's tets (the length that plane
    tolerances are relative to)."""
    nodes = np.asarray(mesh.nodes, float)
    corners = np.asarray(mesh.tets)[:, :4]
    pairs = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
    lengths = np.concatenate([np.linalg.norm(nodes[corners[:, i]] - nodes[corners[:, j]], axis=1) for i, j in pairs])
    return float(np.median(lengths))


def select_plane_nodes(
    mesh,
    plane: tuple[np.ndarray, np.ndarray],
    *,
    relative_tolerance: float = DEFAULT_PLANE_TOLERANCE,
) -> np.ndarray:
    """Indices (n_face,) of the nodes within ``relative_tolerance * mesh_size(mesh)`` [m]
    of the plane ``(point, normal)`` [m]. Raises ``ValueError`` if the nodes found do not
    span a surface (fewer than 3 non-collinear nodes)."""
    point, normal = (np.asarray(v, float).reshape(3) for v in plane)
    norm = np.linalg.norm(normal)
    if not norm > 0:
        raise ValueError("plane normal must be a non-zero vector")
    if not relative_tolerance > 0:
        raise ValueError(f"relative_tolerance={relative_tolerance} must be > 0")
    nodes = np.asarray(mesh.nodes, float)
    tolerance = relative_tolerance * mesh_size(mesh)
    distance = np.abs((nodes - point) @ (normal / norm))
    found = np.flatnonzero(distance <= tolerance)
    if found.size < 3 or np.linalg.matrix_rank(nodes[found] - nodes[found].mean(axis=0), tol=tolerance) < 2:
        raise ValueError(
            f"only {found.size} node(s) lie within {tolerance:.3g} m of the plane through {point} with normal "
            f"{normal}; the plane must be a face of the mesh (check the point and normal, or raise "
            "relative_tolerance if the mesher moved the face nodes off the plane)"
        )
    return found


def coupling_map(n_nodes: int, nodes: np.ndarray, couplings: list) -> CouplingMap:
    """Transformation T eliminating the slave DOFs of kinematic couplings (``RigidCoupling``
    or any with ``nodes``, ``fixed`` and ``slave_modes``, module docstring).

    n_nodes: number of mesh nodes; nodes (n_nodes, 3) [m]; couplings: slave sets must be
    disjoint. Returns a ``CouplingMap`` (see the module docstring for the layout)."""
    nodes = np.asarray(nodes, float)
    is_slave = np.zeros(n_nodes, bool)
    for coupling in couplings:
        if coupling.nodes.max() >= n_nodes:
            raise ValueError("a coupling refers to a node index beyond the mesh")
        if is_slave[coupling.nodes].any():
            raise ValueError("two rigid couplings share slave nodes; their faces must be disjoint")
        is_slave[coupling.nodes] = True

    free_nodes = np.flatnonzero(~is_slave)
    free_node_dofs = (3 * free_nodes[:, None] + np.arange(3)).ravel()
    n_nodal = free_node_dofs.size
    rows = [free_node_dofs]
    cols = [np.arange(n_nodal)]
    vals = [np.ones(n_nodal)]
    master_dofs: list[np.ndarray | None] = []
    next_col = n_nodal
    for coupling in couplings:
        if coupling.fixed:
            master_dofs.append(None)
            continue
        s = coupling.nodes
        modes = coupling.slave_modes(nodes[s])  # (n_s, 3, n_master): u_s = modes q
        master = np.arange(next_col, next_col + modes.shape[2])
        master_dofs.append(master)
        next_col += modes.shape[2]
        slave_rows = 3 * s[:, None] + np.arange(3)  # (n_s, 3)
        rows.append(np.repeat(slave_rows.ravel(), modes.shape[2]))
        cols.append(np.broadcast_to(master, modes.shape).ravel())
        vals.append(modes.ravel())  # zeros (a rigid mode's) are dropped below
    T = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n_nodes, next_col)
    )
    T.eliminate_zeros()
    return CouplingMap(transform=T, master_dofs=tuple(master_dofs), free_node_dofs=free_node_dofs)


def rigid_body_modes(nodes: np.ndarray, origin: np.ndarray | None = None) -> np.ndarray:
    """The six rigid-body displacement fields (3 n_nodes, 6) [m per unit twist] of nodes
    (n_nodes, 3) [m]: columns translate along x, y, z and rotate about x, y, z through
    ``origin`` (default: the centroid, for conditioning)."""
    nodes = np.asarray(nodes, float)
    origin = nodes.mean(axis=0) if origin is None else np.asarray(origin, float)
    modes = np.zeros((len(nodes), 3, 6))
    modes[:, :, :3] = np.eye(3)
    modes[:, :, 3:] = -skew(nodes - origin)  # theta x r = -[r]x theta
    return modes.reshape(-1, 6)


def eliminate_dofs(
    K: sp.spmatrix, f: np.ndarray, dofs: np.ndarray, values: np.ndarray
) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """Prescribe ``u[dofs] = values`` by elimination.

    Returns (K_ff, f_f - K_fp values, free) with ``free`` the remaining DOF indices; after
    solving ``K_ff u_f = rhs`` set ``u[free] = u_f``, ``u[dofs] = values``. f may be
    (n,) or (n, k)."""
    n = K.shape[0]
    dofs = np.asarray(dofs, dtype=np.int64)
    values = np.asarray(values, float)
    if dofs.shape != values.shape[:1]:
        raise ValueError(f"dofs {dofs.shape} and values {values.shape} must have the same length")
    prescribed = np.zeros(n, bool)
    prescribed[dofs] = True
    free = np.flatnonzero(~prescribed)
    K = sp.csr_matrix(K)
    K_free = K[free]
    rhs = np.asarray(f, float)[free] - K_free[:, dofs] @ values
    return K_free[:, free].tocsr(), rhs, free
