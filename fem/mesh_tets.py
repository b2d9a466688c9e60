"""The quadratic tet mesh type shared by the mesher and the FEM.

``TetMesh(nodes, tets)``: nodes (n_nodes, 3) [m], tets (n_tets, 10) in VTK order
(corners 0-3, then mid-edge nodes of edges 01, 12, 02, 03, 13, 23), every corner tet
with positive volume. ``linear_to_quadratic`` adds the mid-edge nodes to a linear mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh_quality import EDGES, corner_volumes, p2_volumes, unique_rows

__all__ = ["TetMesh", "linear_to_quadratic"]


@dataclass(frozen=True, eq=False)
class TetMesh:
    """Quadratic tetrahedral mesh.

    nodes (n_nodes, 3) float [m]; tets (n_tets, 10) int, VTK order: corners 0-3, then
    mid-edge nodes of edges 01, 12, 02, 03, 13, 23. Every corner tet has positive volume
    (checked). Arrays are stored read-only.
    """

    nodes: np.ndarray
    tets: np.ndarray

    def __post_init__(self) -> None:
        nodes = np.array(self.nodes, dtype=float)
        tets = np.array(self.tets, dtype=np.int64)
        if nodes.ndim != 2 or nodes.shape[1] != 3:
            raise ValueError(f"nodes must have shape (n_nodes, 3), got {nodes.shape}")
        if tets.ndim != 2 or tets.shape[1] != 10:
            raise ValueError(f"tets must have shape (n_tets, 10) (quadratic, VTK order), got {tets.shape}")
        if tets.size and (tets.min() < 0 or tets.max() >= len(nodes)):
            raise ValueError(f"tets index nodes outside 0..{len(nodes) - 1}")
        if not np.isfinite(nodes).all():
            raise ValueError("nodes must be finite")
        volume = corner_volumes(nodes, tets)
        if tets.size and volume.min() <= 0:
            bad = int(np.sum(volume <= 0))
            raise ValueError(f"{bad} tets have non-positive volume; order corners so that "
                             "(p1 - p0) x (p2 - p0) . (p3 - p0) > 0 (VTK order)")
        nodes.setflags(write=False)
        tets.setflags(write=False)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "tets", tets)

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_tets(self) -> int:
        return len(self.tets)

    @property
    def n_dof(self) -> int:
        """3 displacement DOFs per node."""
        return 3 * len(self.nodes)

    @property
    def corner_tets(self) -> np.ndarray:
        """(n_tets, 4) corner node indices."""
        return self.tets[:, :4]

    @property
    def volume(self) -> float:
        """Volume [m^3] of the curved quadratic mesh."""
        return float(p2_volumes(self.nodes, self.tets).sum())


def linear_to_quadratic(nodes: np.ndarray, tets4: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Add one mid-node per edge (shared by all tets of that edge).

    nodes (n, 3), tets4 (m, 4) -> nodes (n + n_edges, 3), tets (m, 10) in VTK order,
    edges (n_edges, 2) corner indices of the edge whose mid-node is n + k.
    """
    pairs = np.sort(tets4[:, EDGES].reshape(-1, 2), axis=1)
    edges, _, inverse = unique_rows(pairs, len(nodes), return_inverse=True)
    mid = 0.5 * (nodes[edges[:, 0]] + nodes[edges[:, 1]])
    tets = np.concatenate([tets4, len(nodes) + inverse.reshape(-1, 6)], axis=1)
    return np.concatenate([nodes, mid]), tets, edges
