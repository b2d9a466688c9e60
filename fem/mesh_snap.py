"""From a linear tet mesh of a part to a quadratic mesh on the exact surfaces, measured.

``snap_to_part`` classifies the boundary, moves boundary nodes onto the analytic
surfaces (``flexcal.fem.mesh_projection``), lets the interior follow (harmonic
extension), repairs the few tets this flattens, adds mid-edge nodes (projected onto
curved surfaces too) and measures the geometry before and after: volume, largest
surface deviation, end-plane flatness, neck thickness and elements through it.

Repair: fTetWild does not keep sharp edges; within its envelope it may cut a corner with
a strip of triangles. Nodes of that strip are put on the edge line, and a triangle whose
three nodes all land on the line flattens its tet. Such nodes are demoted, one round at
a time, to the single nearest face (the corner keeps a chamfer no larger than the
envelope there); boundary nodes of tets still inverted after that stay where fTetWild
put them; a mid-edge node whose projection folds a curved element stays on the chord.
The counts are reported (``n_demoted``, ``n_unsnapped``, ``n_straight_mid``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from flexcal.geometry.exact import ThinSection, exact_volume, thin_sections
from flexcal.geometry.surfaces import boundary_patches

from .mesh_projection import (boundary_faces, classify_faces, extend_displacement, node_patch_sets,
                              project_nodes)
from .mesh_quality import (corner_volumes, edge_lengths, min_dihedral_angle, p2_jacobian_determinants,
                           radius_ratio, tets_crossed_by_line, unique_rows)
from .mesh_tets import TetMesh, linear_to_quadratic

__all__ = ["NeckReport", "InvertedElementsError", "snap_to_part", "MAX_REPAIR_ROUNDS"]

#: rounds of demoting edge nodes / unsnapping nodes before giving up
MAX_REPAIR_ROUNDS = 8


class InvertedElementsError(RuntimeError):
    """Snapping onto the exact surfaces left inverted elements that could not be repaired."""


@dataclass(frozen=True, kw_only=True)
class NeckReport:
    """How a thin section came out. Thicknesses [m]: ``thickness_mesh`` is t plus the
    mean offset, along the thin axis, of the nodes on the section's thin faces near the
    neck (|x - neck_x| <= neck half length) from the exact surfaces, summed over both
    sides; ``thickness_min`` takes the most inward node of each side; ``*_raw`` are the
    same for the mesher's output before snapping (corner nodes only).
    ``elements_across``: t / median corner-edge length of the tets crossed by five lines
    through the neck along the thin axis; ``tets_crossed``: median number of tets per line."""

    name: str
    thickness_exact: float
    thickness_mesh: float
    thickness_min: float
    thickness_mesh_raw: float
    thickness_min_raw: float
    elements_across: float
    tets_crossed: float

    @property
    def thickness_error(self) -> float:
        """Relative error of the mean neck thickness of the final mesh."""
        return self.thickness_mesh / self.thickness_exact - 1.0

    @property
    def thickness_error_raw(self) -> float:
        """Relative error of the mean neck thickness before snapping."""
        return self.thickness_mesh_raw / self.thickness_exact - 1.0


# ----------------------------------------------------------------------------------------
# measurements


def _section_patch_ids(patches, section: ThinSection) -> set[int]:
    """Patches forming the two thin faces of a section (flat leaf faces, fillets, notch
    cylinders): the patches of that piece other than its side caps."""
    prefix = f"{section.name}:"
    caps = {f"{prefix}{s}{'xyz'[section.width_axis]}" for s in "+-"}
    return {k for k, p in enumerate(patches) if p.name.startswith(prefix) and p.name not in caps}


def _neck_thickness(nodes: np.ndarray, node_sets: dict[int, tuple[int, ...]], patches,
                    section: ThinSection) -> tuple[float, float]:
    """(mean, min) neck thickness [m], see ``NeckReport``."""
    thin_ids = _section_patch_ids(patches, section)
    ids = np.array([i for i, ks in node_sets.items() if thin_ids.intersection(ks)], dtype=np.int64)
    if len(ids) == 0:
        return float("nan"), float("nan")
    p = nodes[ids]
    near = np.abs(p[:, 0] - section.neck_x) <= section.neck_half_length
    mean, low = section.neck_thickness, section.neck_thickness
    for side in (-1, 1):
        q = p[near & (side * p[:, section.thin_axis] > 0)]
        if len(q) == 0:
            return float("nan"), float("nan")
        offsets = side * q[:, section.thin_axis] - section.thickness(q[:, 0]) / 2
        mean += offsets.mean()
        low += offsets.min()
    return float(mean), float(low)


def _elements_across(nodes: np.ndarray, tets4: np.ndarray, section: ThinSection) -> tuple[float, float]:
    counts, lengths = [], []
    direction = np.zeros(3)
    direction[section.thin_axis] = 1.0
    for fraction in (-0.6, -0.3, 0.0, 0.3, 0.6):
        origin = np.zeros(3)
        origin[0] = section.neck_x
        origin[section.width_axis] = fraction * section.half_width
        crossed = tets_crossed_by_line(nodes, tets4, origin, direction)
        counts.append(len(crossed))
        lengths.append(edge_lengths(nodes, tets4[crossed]).ravel())
    if sum(counts) == 0:
        return float("nan"), 0.0
    return float(section.neck_thickness / np.median(np.concatenate(lengths))), float(np.median(counts))


def _jacobian_ratios(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Per element: smallest det J of the quadratic map at the corners, centroid and
    Keast points, over 6 x the straight tet's volume (1 for a straight-sided tet)."""
    points = np.concatenate([np.eye(4), np.full((1, 4), 0.25),
                             [np.roll([0.5, 1 / 6, 1 / 6, 1 / 6], k) for k in range(4)]])
    det = p2_jacobian_determinants(nodes, tets, points)
    return det.min(axis=1) / (6.0 * corner_volumes(nodes, tets))


def _max_deviation(nodes: np.ndarray, node_sets: dict[int, tuple[int, ...]], patches) -> float:
    """Largest distance [m] of a classified boundary node from the surfaces it belongs to."""
    by_patch: dict[int, list[int]] = {}
    for i, ks in node_sets.items():
        for k in ks:
            by_patch.setdefault(k, []).append(i)
    return max([float(patches[k].surface_distance(nodes[np.array(ids)]).max()) for k, ids in by_patch.items()],
               default=0.0)


# ----------------------------------------------------------------------------------------
# snapping


def _mid_node_sets(nodes10: np.ndarray, edges: np.ndarray, n_corner: int, node_sets: dict[int, tuple[int, ...]],
                   faces_b: np.ndarray, patches, tolerance: float) -> dict[int, tuple[int, ...]]:
    """Patches of the mid-nodes of boundary edges: those both end nodes lie on; where
    they share none (an edge across the tangent line between a flat leaf face and its
    fillet) the nearest of their patches, if the mid-node is within ``tolerance`` [m]."""
    keys = unique_rows(np.sort(faces_b[:, [[0, 1], [1, 2], [0, 2]]].reshape(-1, 2), axis=1), n_corner)[0]
    # edges are sorted by (a, b) (unique_rows), so a key's edge index is a binary search
    edge_key = edges[:, 0].astype(np.int64) * n_corner + edges[:, 1]
    index = np.searchsorted(edge_key, keys[:, 0] * n_corner + keys[:, 1])
    out: dict[int, tuple[int, ...]] = {}
    for (a, b), k in zip(keys.tolist(), index.tolist()):
        sa, sb = node_sets.get(a, ()), node_sets.get(b, ())
        mid = n_corner + k
        shared = set(sa).intersection(sb)
        if shared:
            out[mid] = tuple(sorted(shared))
            continue
        candidates = sorted(set(sa).union(sb))
        if candidates:
            distance = [float(patches[k].distance(nodes10[mid][None])[0]) for k in candidates]
            if min(distance) <= tolerance:
                out[mid] = (candidates[int(np.argmin(distance))],)
    return out


def _snapped(raw: np.ndarray, tets4: np.ndarray, boundary: np.ndarray, node_sets: dict[int, tuple[int, ...]],
             patches, morph: bool) -> np.ndarray:
    """Node positions with the boundary on its patches (boundary nodes without patches
    stay put) and, with ``morph``, the interior following harmonically."""
    target = project_nodes(raw, node_sets, patches)
    if not morph:
        return target
    out = raw + extend_displacement(tets4, len(raw), boundary, target[boundary] - raw[boundary])
    out[boundary] = target[boundary]
    return out


def _repair_round(bad_tets: np.ndarray, tets4: np.ndarray, raw: np.ndarray,
                  node_sets: dict[int, tuple[int, ...]], patches) -> tuple[int, int]:
    """Demote the multi-patch nodes of the bad tets to their nearest patch; where a bad
    tet has none, unsnap its boundary nodes. Returns (n_demoted, n_unsnapped)."""
    ids = np.unique(tets4[bad_tets])
    demoted = 0
    for i in ids.tolist():
        ks = node_sets.get(i, ())
        if len(ks) > 1:
            distance = [float(patches[k].distance(raw[i][None])[0]) for k in ks]
            node_sets[i] = (ks[int(np.argmin(distance))],)
            demoted += 1
    if demoted:
        return demoted, 0
    unsnapped = 0
    for i in ids.tolist():
        if node_sets.pop(i, None) is not None:
            unsnapped += 1
    return 0, unsnapped


def snap_to_part(params, nodes: np.ndarray, tets4: np.ndarray, *, tolerance: float, project: bool = True,
                 morph: bool = True) -> tuple[TetMesh, dict[str, Any]]:
    """Quadratic mesh from a linear tet mesh of the part, with the boundary snapped onto
    the exact surfaces; plus measurements of the input and output geometry.

    params: the hinge or chain parameters; nodes (n, 3) [m] and tets4 (m, 4) with
    positive volumes, in the part frame; tolerance [m]: how far a boundary node may be
    from a surface and still be put on it (a few times the mesher's envelope). With
    ``morph`` the interior follows the snapped boundary. Returns the mesh and a dict of
    the ``MeshReport`` fields it measured. Raises ``InvertedElementsError`` if inverted
    elements remain after the repair rounds (see module doc).
    """
    raw = np.asarray(nodes, float)
    tets4 = np.asarray(tets4, dtype=np.int64)
    patches = boundary_patches(params)
    sections = thin_sections(params)
    v_exact = exact_volume(params)
    faces_b = boundary_faces(tets4)
    face_patch, _ = classify_faces(raw, faces_b, patches)
    node_sets = node_patch_sets(raw, faces_b, face_patch, patches, tolerance)
    boundary = np.unique(faces_b)
    measured: dict[str, Any] = dict(
        volume_error_raw=float(corner_volumes(raw, tets4).sum()) / v_exact - 1.0,
        max_surface_deviation_raw=_max_deviation(raw, node_sets, patches),
        n_unassigned=int(len(boundary) - len(node_sets)), n_demoted=0, n_unsnapped=0, n_straight_mid=0)
    necks_raw = [_neck_thickness(raw, node_sets, patches, s) for s in sections]

    nodes = raw
    if project:
        for _ in range(MAX_REPAIR_ROUNDS + 1):
            nodes = _snapped(raw, tets4, boundary, node_sets, patches, morph)
            bad = np.nonzero(corner_volumes(nodes, tets4) <= 0)[0]
            if len(bad) == 0:
                break
            demoted, unsnapped = _repair_round(bad, tets4, raw, node_sets, patches)
            measured["n_demoted"] += demoted
            measured["n_unsnapped"] += unsnapped
            if demoted + unsnapped == 0:
                break
        if len(bad):
            raise InvertedElementsError(f"{len(bad)} tets stay inverted after snapping the boundary onto the "
                                        f"exact surfaces ({measured['n_demoted']} edge nodes demoted, "
                                        f"{measured['n_unsnapped']} nodes unsnapped)")
    n_corner = len(nodes)
    nodes10, tets10, edges = linear_to_quadratic(nodes, tets4)
    mid_sets = _mid_node_sets(nodes10, edges, n_corner, node_sets, faces_b, patches, tolerance)
    if project:
        chord = nodes10.copy()
        nodes10 = project_nodes(nodes10, mid_sets, patches)
        # keep straight edges where curving them folds an element: per folded element the
        # mid-node that moved most goes back to its chord, until none is folded
        for _ in range(6 * MAX_REPAIR_ROUNDS):
            folded = np.nonzero(_jacobian_ratios(nodes10, tets10) <= 0)[0]
            if len(folded) == 0:
                break
            mids = tets10[folded, 4:]
            moved = np.linalg.norm(nodes10[mids] - chord[mids], axis=2)
            straight = np.unique(mids[np.arange(len(folded)), np.argmax(moved, axis=1)])
            straight = straight[np.linalg.norm(nodes10[straight] - chord[straight], axis=1) > 0]
            if len(straight) == 0:
                break
            nodes10[straight] = chord[straight]
            for i in straight.tolist():
                mid_sets.pop(i, None)
            measured["n_straight_mid"] += len(straight)
    mesh = TetMesh(nodes10, tets10)
    jacobian = float(_jacobian_ratios(mesh.nodes, mesh.tets).min())
    if jacobian <= 0:
        raise InvertedElementsError(f"a quadratic element is folded (min det J ratio {jacobian:.3g})")

    all_sets = {**node_sets, **mid_sets}
    end_deviation = 0.0
    for k, patch in enumerate(patches):
        if patch.name.startswith("end:"):
            ids = np.array([i for i, ks in all_sets.items() if k in ks], dtype=np.int64)
            if len(ids):
                end_deviation = max(end_deviation, float(patch.surface_distance(mesh.nodes[ids]).max()))
    necks = []
    for s, (raw_mean, raw_min) in zip(sections, necks_raw):
        thick, thin = _neck_thickness(mesh.nodes, all_sets, patches, s)
        across, crossed = _elements_across(mesh.nodes, tets4, s)
        necks.append(NeckReport(name=s.name, thickness_exact=s.neck_thickness, thickness_mesh=thick,
                                thickness_min=thin, thickness_mesh_raw=raw_mean, thickness_min_raw=raw_min,
                                elements_across=across, tets_crossed=crossed))
    quality = radius_ratio(mesh.nodes, tets4)
    volume = mesh.volume
    measured.update(
        n_corner_nodes=n_corner, radius_ratio_min=float(quality.min()), radius_ratio_median=float(np.median(quality)),
        min_dihedral_deg=float(min_dihedral_angle(mesh.nodes, tets4).min()), min_jacobian_ratio=jacobian,
        volume=volume, volume_exact=v_exact, volume_error=volume / v_exact - 1.0,
        max_surface_deviation=_max_deviation(mesh.nodes, all_sets, patches), end_plane_deviation=end_deviation,
        necks=tuple(necks))
    return mesh, measured


def boundary_node_sets(params, nodes: np.ndarray, tets4: np.ndarray, tolerance: float
                       ) -> tuple[Sequence, dict[int, tuple[int, ...]]]:
    """(patches, node -> patch indices) for a linear mesh: which exact surface each
    boundary node is taken to lie on (for tests and diagnostics)."""
    patches = boundary_patches(params)
    faces_b = boundary_faces(np.asarray(tets4, dtype=np.int64))
    face_patch, _ = classify_faces(nodes, faces_b, patches)
    return patches, node_patch_sets(nodes, faces_b, face_patch, patches, tolerance)
