"""Snap the boundary nodes of a tet mesh onto the exact analytic surfaces of the part.

fTetWild keeps its output surface only within an envelope of the input triangles, so
boundary vertices sit up to ``epsilon`` off the true faces: a notch neck comes out
thinner or thicker, end-face nodes leave their plane. With the surfaces known exactly
(``flexcal.geometry.surfaces.boundary_patches``), every boundary node is put back:

1. each boundary triangle is assigned the patch it lies on: among the patches whose
   outward normal agrees with the triangle's within 60 deg, the nearest one;
2. a node belongs to the patches of its triangles, keeping only those it is within
   ``tolerance`` of (so a stray triangle cannot drag a node across a face), and of two
   patches that meet tangentially (a flat leaf face and its fillet) only the nearer;
3. the node is moved to the intersection of its patches: a face (1 patch), an edge
   (2: two planes, or a plane and a cylinder) or a corner (3). Planes fix a
   coordinate; a cylinder then fixes the remaining in-plane coordinate (the root
   nearest the node) or, with none fixed, is a radial projection.

Mid-edge nodes of boundary edges are projected onto the patches both end nodes share,
which puts quadratic nodes on the curved notch and fillet surfaces instead of on the
chord.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence, Union

import numpy as np

from flexcal.geometry.surfaces import CylinderPatch, PlanePatch

from .mesh_quality import EDGES, unique_rows

__all__ = ["boundary_faces", "classify_faces", "tangent_pairs", "node_patch_sets", "project_onto", "project_nodes",
           "extend_displacement", "FACE_ORDER"]

Patch = Union[PlanePatch, CylinderPatch]

#: corner indices of the face opposite each corner of a tet, ordered so that the
#: normal (b - a) x (c - a) points out of a positively oriented tet
FACE_ORDER = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def boundary_faces(tets4: np.ndarray) -> np.ndarray:
    """Faces (n_faces, 3) that belong to one tet only, oriented outwards, from corner
    tets (n_tets, 4) with positive volume."""
    faces = tets4[:, FACE_ORDER].reshape(-1, 3)
    _, index, counts = unique_rows(np.sort(faces, axis=1), int(tets4.max()) + 1, return_counts=True)
    return faces[index[counts == 1]]


def classify_faces(nodes: np.ndarray, faces: np.ndarray, patches: Sequence[Patch],
                   max_angle_deg: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """Patch index (n_faces,) of every boundary face and the face centroid's distance
    (n_faces,) [m] to it. Faces whose normal agrees with no patch get the nearest patch."""
    p = nodes[faces]
    centroid = p.mean(axis=1)
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    distance = np.stack([patch.distance(centroid) for patch in patches], axis=1)
    agree = np.stack([np.einsum("ij,ij->i", normal, patch.normal(centroid)) for patch in patches], axis=1)
    penalised = np.where(agree >= np.cos(np.radians(max_angle_deg)), distance, np.inf)
    best = np.argmin(penalised, axis=1)
    none_agree = ~np.isfinite(penalised.min(axis=1))
    best[none_agree] = np.argmin(distance[none_agree], axis=1)
    return best, distance[np.arange(len(faces)), best]


def tangent_pairs(patches: Sequence[Patch], rtol: float = 1e-9) -> set[tuple[int, int]]:
    """Index pairs (i < j) of a plane and a curved patch that meet tangentially (a flat leaf
    face running into its fillet, a fillet running into a block face): their common
    line is no edge of the solid, so a node there belongs to one of them only."""
    out = set()
    for i, a in enumerate(patches):
        for j, b in enumerate(patches):
            if i < j and isinstance(a, PlanePatch) != isinstance(b, PlanePatch):
                plane, curved = (a, b) if isinstance(a, PlanePatch) else (b, a)
                if curved.is_tangent_to(plane, rtol):
                    out.add((i, j))
    return out


def node_patch_sets(nodes: np.ndarray, faces: np.ndarray, face_patch: np.ndarray,
                    patches: Sequence[Patch], tolerance: float) -> dict[int, tuple[int, ...]]:
    """For every boundary node, the sorted patch indices it lies on (see module doc).

    Of two tangent patches (``tangent_pairs``) a node keeps the nearer one only."""
    node = faces.ravel()
    patch = np.repeat(face_patch, 3)
    pairs = np.unique(np.stack([node, patch], axis=1), axis=0)
    distance = np.empty(len(pairs))
    for k, pat in enumerate(patches):
        sel = pairs[:, 1] == k
        if sel.any():
            distance[sel] = pat.distance(nodes[pairs[sel, 0]])
    keep = distance <= tolerance
    pairs, distance = pairs[keep], distance[keep]
    out: dict[int, dict[int, float]] = {}
    for (n, k), d in zip(pairs.tolist(), distance.tolist()):
        out.setdefault(n, {})[k] = d
    tangent = tangent_pairs(patches)
    result: dict[int, tuple[int, ...]] = {}
    for n, dist in out.items():
        ks = sorted(dist)
        if len(ks) > 1 and tangent:
            for i, j in tangent:
                if i in dist and j in dist and i in ks and j in ks:
                    ks.remove(j if dist[j] > dist[i] else i)
        result[n] = tuple(ks)
    return result


def project_onto(points: np.ndarray, patches: Sequence[Patch]) -> np.ndarray:
    """Points (n, 3) moved to the intersection of the given patches' surfaces (unbounded).

    Planes fix their coordinate (a second plane on the same axis is ignored); a curved
    patch (cylinder, or a profile's own) then solves for its free in-plane coordinate or
    projects onto itself (``project_constrained``). Combinations with no such solution (a
    curved patch whose two in-plane coordinates are both fixed, two curved patches) keep
    the curved patch out and use the planes only.
    """
    out = np.array(points, float, copy=True)
    fixed: set[int] = set()
    for patch in patches:
        if isinstance(patch, PlanePatch) and patch.axis not in fixed:
            out[:, patch.axis] = patch.value
            fixed.add(patch.axis)
    curved = [p for p in patches if not isinstance(p, PlanePatch)]
    if len(curved) != 1:
        return out
    return curved[0].project_constrained(out, fixed)


@dataclass(frozen=True)
class _Group:
    patch_ids: tuple[int, ...]
    node_ids: np.ndarray


def _groups(node_sets: dict[int, tuple[int, ...]]) -> list[_Group]:
    by_set: dict[tuple[int, ...], list[int]] = {}
    for n, ks in node_sets.items():
        by_set.setdefault(ks, []).append(n)
    return [_Group(ks, np.array(ns, dtype=np.int64)) for ks, ns in by_set.items()]


def project_nodes(nodes: np.ndarray, node_sets: dict[int, tuple[int, ...]], patches: Sequence[Patch]) -> np.ndarray:
    """Copy of nodes (n, 3) with every node of ``node_sets`` moved onto its patches."""
    out = np.array(nodes, float, copy=True)
    for group in _groups(node_sets):
        out[group.node_ids] = project_onto(out[group.node_ids], [patches[k] for k in group.patch_ids])
    return out


def extend_displacement(tets4: np.ndarray, n_nodes: int, moved: np.ndarray, displacement: np.ndarray) -> np.ndarray:
    """Spread the displacement (k, 3) [m] of the ``moved`` nodes (k,) into the rest of
    the mesh as a discrete harmonic field (graph Laplacian of the tet edges, moved nodes
    held): nodes next to a snapped boundary node follow it, so a thin boundary tet is
    carried along instead of being squashed. Returns displacements (n_nodes, 3)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

    edges = unique_rows(np.sort(tets4[:, EDGES].reshape(-1, 2), axis=1), n_nodes)[0]
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    adjacency = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_nodes, n_nodes)).tocsr()
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    laplacian = (coo_matrix((degree, (np.arange(n_nodes), np.arange(n_nodes))), shape=(n_nodes, n_nodes))
                 - adjacency).tocsr()
    out = np.zeros((n_nodes, 3))
    out[moved] = displacement
    free = np.setdiff1d(np.arange(n_nodes), moved)
    if len(free) == 0:
        return out
    l_ff = laplacian[free][:, free].tocsc()
    rhs = -(laplacian[free][:, moved] @ displacement)
    out[free] = np.asarray(spsolve(l_ff, rhs)).reshape(len(free), 3)
    return out
