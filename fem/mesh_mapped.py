"""Deterministic mapped quadratic-tet meshes of single hinges (any profile with a mapped outline).

fTetWild seeds its own random generator from ``std::random_device`` (fTetWild's
``RandomSource.h``; pytetwild exposes no seed), so two ``mesh_part`` calls on the same
solid give different meshes even with one thread: measured 13,635 / 13,659 / 14,089
nodes for the R 5, t 1, b 10 mm notch at 3 elements through. A single hinge is a
profile t(x) extruded along its width, so a tensor grid mapped onto it is exact and the
same on every run and machine (the outline per profile: ``flexcal.fem.profiles``): x graded along the hinge (finer where the section is thin
and where the fillet arc turns), y the fraction of the local height, z uniform across the
width. The linear grid then goes through the same snapping and measuring as a fTetWild
mesh (``flexcal.fem.mesh_snap.snap_to_part``: mid-edge nodes projected onto the exact
arcs, the ``MeshReport``), so the FEM and the report see the same kind of mesh.

Hinge frame as in ``flexcal.geometry.params``; SI.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np

from .mesh import MeshReport, TetMesh
from .mesh_snap import _jacobian_ratios, snap_to_part
from .profiles import MappedOutline, outline_of
from .structured import _EDGES, _folded_tets, _straighten, grid_tet_mesh

if TYPE_CHECKING:
    from flexcal.geometry.solids import Part

__all__ = ["mapped_mesh_supported", "mapped_grid", "mapped_mesh_part", "hinge_outline", "isoparametric_mesh",
           "MAX_MAPPED_DOF"]

# Largest mesh built on request, an estimate (not measured): 136k DOF took 6.5 GB with
# spsolve (docs/fem.md), so 11x that would not fit a workstation; beyond it the run would
# be killed for memory long after it started instead of being refused up front.
MAX_MAPPED_DOF = 1_500_000


def mapped_mesh_supported(params) -> bool:
    """True when the part is a hinge whose profile has a mapped outline for it
    (``flexcal.fem.profiles``): notch hinges, leaf hinges whose blocks are as high as their
    fillets reach (t + 2a, the default), ..."""
    return outline_of(params) is not None


def hinge_outline(hinge) -> MappedOutline:
    outline = outline_of(hinge)
    if outline is None:
        raise ValueError(f"the mapped mesher has no outline for this {type(hinge).__name__} (a leaf with blocks "
                         f"higher than t + 2a, or a part that is no single hinge); use the tetwild mesher")
    return outline


def mapped_grid(hinge, n_thickness: int, *, aspect: float = 2.0,
                n_arc: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corner coordinates (x [m], eta [-] in [-1/2, 1/2], z [m]) of the mapped grid.

    ``n_thickness`` cells across the local height; cells at most ``aspect`` times as long
    and wide as they are high at the neck, growing with the height along the arcs, and at
    least ``n_arc`` cells along each quarter arc; about square cells on the blocks.
    """
    outline = hinge_outline(hinge)
    c, rho, t = outline.flat_half_length, outline.arc_half_length, outline.neck_thickness
    block, width = outline.block_length, outline.width
    n = int(n_thickness)
    half = [0.0]
    if c > 0:
        n_flat = max(1, math.ceil(c / (aspect * t / n)))
        half += list(np.linspace(0.0, c, n_flat + 1)[1:])
    if rho > 0:
        phi = np.linspace(0.0, 0.5 * np.pi, 8001)  # x = c + rho sin(phi): fine where the arc turns
        x = c + rho * np.sin(phi)
        density = np.maximum(n * rho * np.cos(phi) / (aspect * outline.height(x)), 2.0 * n_arc / np.pi)
        s = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(phi))])
        n_cells = max(1, math.ceil(s[-1]))
        arc = np.interp(np.linspace(0.0, s[-1], n_cells + 1), s, x)[1:]
        arc[-1] = c + rho
        half += list(arc)
    half = np.array(half)
    end = c + rho
    height = outline.block_height
    n_block = max(1, math.ceil(block / (height / n)))
    blocks = np.linspace(end, end + block, n_block + 1)[1:]
    x = np.concatenate([-blocks[::-1], -half[::-1], half[1:], blocks])
    n_width = max(2, math.ceil(width / (aspect * t / n)))
    return x, np.linspace(-0.5, 0.5, n + 1), np.linspace(-width / 2, width / 2, n_width + 1)


def isoparametric_mesh(mesh: TetMesh, height) -> tuple[TetMesh, int]:
    """The mesh with every mid-edge node at the image of its edge's midpoint in the
    parent grid (x, eta = y / h(x), z; h = ``height(x)`` [m]): curved elements that follow the profile inside
    the part too, not only on its surface (measured: C_rz,Mz -1.3 % of converged with
    surface-projected mid-nodes only, -0.6 % with these, R 5, t 1, b 10 mm, 3 cells
    across). Tets whose curved map would fold keep straight edges. Returns (mesh, number
    of mid-nodes left straight)."""
    nodes = mesh.nodes.copy()
    tets = mesh.tets
    corners = np.unique(tets[:, :4])
    parent = np.zeros_like(nodes)
    parent[corners] = nodes[corners]
    parent[corners, 1] = nodes[corners, 1] / height(nodes[corners, 0])
    for j, (a, b) in enumerate(_EDGES):
        mid = tets[:, 4 + j]
        point = 0.5 * (parent[tets[:, a]] + parent[tets[:, b]])
        nodes[mid] = point
        nodes[mid, 1] = point[:, 1] * height(point[:, 0])
    straight: set[int] = set()
    for _ in range(10):
        folded = _folded_tets(nodes, tets)
        if folded.size == 0:
            break
        straight.update(tets[folded, 4:].ravel().tolist())
        _straighten(nodes, tets, folded)
    else:  # pragma: no cover - the straight mesh is valid (snap_to_part checked it)
        raise RuntimeError("could not unfold the mapped hinge mesh; use the tetwild mesher")
    return TetMesh(nodes, tets), len(straight)


def mapped_mesh_part(part: "Part", *, elements_through_thickness: float = 3, aspect: float = 2.0,
                     n_arc: int = 8) -> tuple[TetMesh, MeshReport]:
    """Mapped quadratic tet mesh of a hinge ``Part`` and its report (as ``mesh_part``).

    ``elements_through_thickness`` is rounded up to whole cells across the neck (each cell
    splits into six tets, so a line through the neck crosses about that many tets).
    Raises ValueError for a part it cannot map (``mapped_mesh_supported``), bad options or
    a mesh beyond ``MAX_MAPPED_DOF``.
    """
    params = part.params
    outline = outline_of(params)
    if outline is None:
        raise ValueError("the mapped mesher handles single hinges whose profile has a mapped outline (notch "
                         "hinges, leaf hinges with blocks t + 2a high, ...); use the tetwild mesher for this part")
    n_float = float(elements_through_thickness)
    if not (math.isfinite(n_float) and n_float >= 1):
        raise ValueError(f"elements_through_thickness={elements_through_thickness!r} must be >= 1")
    n = math.ceil(n_float - 1e-9)
    timings: dict[str, float] = {}
    cpu0 = time.process_time()
    t0 = time.perf_counter()
    x, eta, z = mapped_grid(params, n, aspect=aspect, n_arc=n_arc)
    n_dof = 3 * (2 * len(x) - 1) * (2 * len(eta) - 1) * (2 * len(z) - 1)
    if n_dof > MAX_MAPPED_DOF:
        raise ValueError(f"the mesh would have {n_dof:,} DOF (limit {MAX_MAPPED_DOF:,}: the solver would run out of "
                         f"memory); use fewer elements through the thickness or a width and length closer to the "
                         f"thickness")
    grid = grid_tet_mesh(x, eta, z)
    used, tets4 = np.unique(grid.tets[:, :4], return_inverse=True)
    tets4 = tets4.reshape(-1, 4)
    nodes = grid.nodes[used].copy()
    t = outline.neck_thickness
    nodes[:, 1] *= outline.height(nodes[:, 0])
    timings["grid"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    # every corner node lies on its surface already; the tolerance only has to catch the
    # mid-edge nodes on the chords of the arcs (sagitta <= rho (1 - cos(pi / (4 n_arc))) for circular arcs),
    # kept well below a neck cell (t / n) so no node is put on a surface it is not on.
    # snap_to_part measures the mesh (the report); the mid-edge nodes are then put where
    # the map sends them (isoparametric), as in structured.notch_hinge_tet_mesh
    h_min = t / n
    tolerance = 0.3 * h_min
    snapped, measured = snap_to_part(params, nodes, tets4, tolerance=tolerance, project=True, morph=False)
    mesh, n_straight = isoparametric_mesh(snapped, outline.height)
    jacobian = float(_jacobian_ratios(mesh.nodes, mesh.tets).min())
    measured.update(min_jacobian_ratio=jacobian, volume=mesh.volume,
                    volume_error=mesh.volume / measured["volume_exact"] - 1.0, n_straight_mid=n_straight)
    timings["snap_and_measure"] = time.perf_counter() - t0
    timings["cpu"] = time.process_time() - cpu0
    report = MeshReport(
        n_nodes=mesh.n_nodes, n_tets=mesh.n_tets, epsilon=0.0, n_retries=0, retry_reasons=(),
        options=dict(mesher="mapped", elements_through_thickness=float(n), aspect=aspect, n_arc=n_arc,
                     n_cells=[len(x) - 1, len(eta) - 1, len(z) - 1]),
        timings=timings, **measured)
    return mesh, report
