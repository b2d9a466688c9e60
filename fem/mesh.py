"""Quadratic tet meshes of hinge and chain solids (CadQuery -> pytetwild -> exact surfaces).

``mesh_part(part)`` tessellates the CadQuery solid, tetrahedralises it with fTetWild
(pytetwild) under a sizing field that puts ``elements_through_thickness`` elements
through every thin section (``flexcal.fem.mesh_sizing``), snaps the boundary nodes back
onto the exact analytic surfaces (``flexcal.fem.mesh_projection``), adds mid-edge nodes
(projected onto curved surfaces too; ``flexcal.fem.mesh_snap``) and measures the
result (``MeshReport``).

The contract with the FEM: ``TetMesh(nodes, tets)`` with nodes (n_nodes, 3) [m] and
tets (n_tets, 10) in VTK order (corners 0-3, mid-edge nodes 01, 12, 02, 03, 13, 23),
every corner tet with positive volume. See docs/meshing.md for the measured accuracy.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from flexcal.geometry.exact import bounding_box, thin_sections

from .mesh_quality import corner_volumes
from .mesh_sizing import default_max_element_size, sizing_grid
from .mesh_snap import InvertedElementsError, NeckReport, snap_to_part
from .mesh_tets import TetMesh, linear_to_quadratic

if TYPE_CHECKING:
    from flexcal.geometry.solids import Part

__all__ = ["TetMesh", "MeshReport", "NeckReport", "mesh_part", "snap_to_part", "linear_to_quadratic"]


# ----------------------------------------------------------------------------------------
# report


@dataclass(frozen=True, kw_only=True)
class MeshReport:
    """What ``mesh_part`` produced and how well. Lengths [m], volumes [m^3], times [s].

    radius_ratio_*: normalised radius ratio of the corner tets (1 = regular);
    min_dihedral_deg: smallest dihedral angle; min_jacobian_ratio: smallest det J of the
    curved quadratic map (corners and quadrature points) over 6 x straight volume;
    epsilon: the fTetWild envelope finally used (relative); n_retries: meshes redone with
    a halved epsilon because snapping inverted elements; timings: wall seconds per stage
    plus "cpu" (process CPU seconds, all threads);
    volume_error / volume_error_raw: curved-mesh volume / exact - 1 after / before
    projection (raw = fTetWild's straight tets); max_surface_deviation(_raw): largest
    distance of a boundary node from its exact surface; end_plane_deviation: largest
    distance of an end-face node from its plane; n_unassigned: boundary nodes farther
    than the tolerance from every patch (left where fTetWild put them); n_demoted: edge
    nodes put on one face only, n_unsnapped: corner nodes left unsnapped,
    n_straight_mid: boundary mid-nodes left on the chord, all to keep elements valid
    (see ``flexcal.fem.mesh_snap``).
    """

    n_nodes: int
    n_tets: int
    n_corner_nodes: int
    radius_ratio_min: float
    radius_ratio_median: float
    min_dihedral_deg: float
    min_jacobian_ratio: float
    volume: float
    volume_exact: float
    volume_error: float
    volume_error_raw: float
    max_surface_deviation: float
    max_surface_deviation_raw: float
    end_plane_deviation: float
    n_unassigned: int
    n_demoted: int
    n_unsnapped: int
    n_straight_mid: int
    necks: tuple[NeckReport, ...]
    epsilon: float
    n_retries: int = 0
    retry_reasons: tuple[str, ...] = ()
    options: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def wall_time(self) -> float:
        """Wall-clock time of the whole ``mesh_part`` call [s]."""
        return float(sum(v for k, v in self.timings.items() if k != "cpu"))

    @property
    def thinnest(self) -> NeckReport | None:
        return min(self.necks, key=lambda n: n.thickness_exact) if self.necks else None


# ----------------------------------------------------------------------------------------
# pytetwild


def _surface_triangles(part: "Part", tolerance: float, angular_tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangulation of the CAD solid (absolute chord tolerance [m], angular tolerance
    [rad]) with the vertices that faces share merged: vertices (n, 3) [m], triangles
    (m, 3) int32 oriented outwards. A copy of the shape is meshed; the Part is untouched."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.TopAbs import TopAbs_REVERSED
    from OCP.TopLoc import TopLoc_Location
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    shape = part.shape.copy()
    BRepMesh_IncrementalMesh(shape.wrapped, tolerance, False, angular_tolerance, False)
    points, triangles, offset = [], [], 0
    for face in shape.Faces():
        location = TopLoc_Location()
        poly = BRep_Tool.Triangulation_s(face.wrapped, location)
        if poly is None:
            raise RuntimeError("CAD triangulation failed for a face; try another surface_tolerance")
        trsf = location.Transformation()
        nodes = [poly.Node(i).Transformed(trsf) for i in range(1, poly.NbNodes() + 1)]
        points.append(np.array([(p.X(), p.Y(), p.Z()) for p in nodes], dtype=float))
        tri = np.array([poly.Triangle(i).Get() for i in range(1, poly.NbTriangles() + 1)], dtype=np.int64) - 1
        if face.wrapped.Orientation() == TopAbs_REVERSED:
            tri = tri[:, [0, 2, 1]]
        triangles.append(tri + offset)
        offset += len(nodes)
    v = np.concatenate(points)
    f = np.concatenate(triangles)
    merge = 1e-9 * float(np.linalg.norm(np.ptp(v, axis=0)))
    pairs = cKDTree(v).query_pairs(merge, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(v), len(v)))
    n_merged, label = connected_components(graph, directed=False)
    merged = np.full((n_merged, 3), np.inf)
    np.minimum.at(merged, label, v)  # the faces' copies differ by round-off; the least, whatever their order
    f = label[f]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    return _canonical_order(merged, f)


_GRID = 2.0**40  # 1 / the rounding step of the surface vertices [1/m]


def _canonical_order(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same triangulation in an order fixed by its coordinates alone: vertices sorted
    by (x, y, z), each triangle turned (orientation kept) to start at its lowest vertex,
    triangles sorted. OCCT lists the faces of a fused solid in an order that changes from
    process to process (the same vertices, shuffled, measured on chain D1; the copies of a
    shared vertex differ by up to 1e-17 m), and fTetWild's mesh depends on the order of its
    input; sorted, the same solid gives the same input. The coordinates are first rounded
    to multiples of 2**-40 m (0.9 pm, exact in binary): OCCT's vertex coordinates vary by
    an ulp with that order too (up to 5e-18 m, on 4 of 712 vertices of chain D1); rounded,
    they agree unless such a pair straddles a half step (odds ~1e-5 per varying
    coordinate). The rounding moves a vertex by <= 0.5 pm, against fTetWild's envelope of
    microns."""
    vertices = np.round(vertices * _GRID) / _GRID
    order = np.lexsort(vertices.T[::-1])
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    f = rank[faces]
    turn = np.argmin(f, axis=1)[:, None]
    f = np.take_along_axis(f, (turn + np.arange(3)) % 3, axis=1)
    f = f[np.lexsort(f.T[::-1])]
    return vertices[order], f.astype(np.int32)


def _tetrahedralize(vertices: np.ndarray, faces: np.ndarray, *, edge_length: float, epsilon: float,
                    background: tuple[np.ndarray, np.ndarray, np.ndarray], num_threads: int,
                    options: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    from .tetwild_process import tetrahedralize_in_child

    bg_points, bg_tets, bg_values = background
    # in a child process: pytetwild resets the SIGINT handler (Ctrl-C would kill us silently)
    nodes, tets = tetrahedralize_in_child(
        vertices, faces, edge_length_abs=edge_length, epsilon=epsilon, vtk_ordering=True,
        optimize=True, num_threads=num_threads, quiet=True,
        bg_vertices=bg_points, bg_tets=bg_tets, bg_values=bg_values, **options)
    nodes = np.asarray(nodes, dtype=float)
    tets = np.asarray(tets, dtype=np.int64)
    if len(tets) == 0:
        raise RuntimeError("pytetwild returned no tets; the surface triangulation may not be closed")
    used, tets = np.unique(tets, return_inverse=True)
    tets = tets.reshape(-1, 4)
    nodes = nodes[used]
    volume = corner_volumes(nodes, tets)
    flip = volume < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return nodes, tets


# ----------------------------------------------------------------------------------------
# the pipeline


def mesh_part(part: "Part", *, elements_through_thickness: float = 3, max_element_size: float | None = None,
              grading: float = 0.5, curvature: float = 0.5, epsilon: float | None = None,
              surface_tolerance: float | None = None, project: bool = True, morph: bool = True,
              max_retries: int = 2, num_threads: int = 0,
              tetwild_options: dict[str, Any] | None = None) -> tuple[TetMesh, MeshReport]:
    """Quadratic tet mesh of a hinge or chain ``Part`` and a report on it.

    elements_through_thickness n: target elements through every thin section (edge
    length t(x)/n, at most ``curvature`` x radius on notches and fillets, growing by
    ``grading`` per unit distance away from the thin section, capped at
    max_element_size [m], default ``default_max_element_size``).
    epsilon: fTetWild's envelope relative to the bounding-box diagonal; default 0.2 x the
    smallest target size / diagonal. The snapping removes the deviation it allows; if
    snapping inverts an element the mesh is redone with epsilon halved, up to
    ``max_retries`` times. surface_tolerance [m]: chord deviation of the CAD
    triangulation (default: half the absolute envelope). project: snap boundary nodes
    (corners and mid-edge nodes) onto the exact surfaces; morph: let the interior follow.
    num_threads: fTetWild threads (0 = all cores). tetwild_options: further keyword
    arguments for ``pytetwild.tetrahedralize`` (e.g. ``stop_energy``).

    Raises ValueError for bad options, RuntimeError if no usable mesh came out.
    """
    params = part.params
    n = float(elements_through_thickness)
    if not (np.isfinite(n) and n >= 1):
        raise ValueError(f"elements_through_thickness={elements_through_thickness!r} must be >= 1")
    h_max = default_max_element_size(params) if max_element_size is None else float(max_element_size)
    if not (np.isfinite(h_max) and h_max > 0):
        raise ValueError(f"max_element_size={max_element_size!r} m must be > 0")
    for name, value in (("grading", grading), ("curvature", curvature)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name}={value!r} must be > 0")
    if int(max_retries) < 0:
        raise ValueError(f"max_retries={max_retries!r} must be >= 0")
    lower, upper = bounding_box(params)
    diagonal = float(np.linalg.norm(upper - lower))
    h_min = min([s.neck_thickness / n for s in thin_sections(params)] + [h_max])
    eps = 0.2 * h_min / diagonal if epsilon is None else float(epsilon)
    if not (0 < eps < 0.1):
        raise ValueError(f"epsilon={epsilon!r} must be in (0, 0.1) (relative to the bounding-box diagonal)")
    if surface_tolerance is not None and not surface_tolerance > 0:
        raise ValueError(f"surface_tolerance={surface_tolerance!r} m must be > 0")
    managed = {"vertices", "faces", "edge_length_abs", "edge_length_fac", "epsilon", "vtk_ordering", "optimize",
               "num_threads", "bg_vertices", "bg_tets", "bg_values"}
    clash = managed.intersection(tetwild_options or {})
    if clash:
        raise ValueError(f"tetwild_options {sorted(clash)} are set by mesh_part; use its own arguments instead")

    timings: dict[str, float] = {}
    cpu0 = time.process_time()
    t0 = time.perf_counter()
    background = sizing_grid(params, n_through=n, h_max=h_max, grading=grading, curvature=curvature)
    timings["sizing"] = time.perf_counter() - t0
    failures = []
    for _ in range(int(max_retries) + 1):
        eps_abs = eps * diagonal
        tol = 0.5 * eps_abs if surface_tolerance is None else float(surface_tolerance)
        t0 = time.perf_counter()
        vertices, faces = _surface_triangles(part, tol, angular_tolerance=0.5)
        timings["tessellation"] = timings.get("tessellation", 0.0) + time.perf_counter() - t0
        t0 = time.perf_counter()
        nodes, tets4 = _tetrahedralize(vertices, faces, edge_length=h_max, epsilon=eps, background=background,
                                       num_threads=num_threads, options=dict(tetwild_options or {}))
        timings["tetwild"] = timings.get("tetwild", 0.0) + time.perf_counter() - t0
        t0 = time.perf_counter()
        try:
            # a node may sit up to the envelope plus the chord error off its surface; x3 margin
            mesh, measured = snap_to_part(params, nodes, tets4, tolerance=3.0 * (eps_abs + tol),
                                          project=project, morph=morph)
            timings["snap_and_measure"] = timings.get("snap_and_measure", 0.0) + time.perf_counter() - t0
            break
        except InvertedElementsError as error:
            timings["snap_and_measure"] = timings.get("snap_and_measure", 0.0) + time.perf_counter() - t0
            failures.append(f"epsilon={eps:.3g}: {error}")
            eps /= 2.0
    else:
        raise RuntimeError("no usable mesh: " + "; ".join(failures) +
                           ". Try more elements_through_thickness or a smaller epsilon.")
    timings["cpu"] = time.process_time() - cpu0
    report = MeshReport(
        n_nodes=mesh.n_nodes, n_tets=mesh.n_tets, epsilon=eps, n_retries=len(failures),
        retry_reasons=tuple(failures),
        options=dict(elements_through_thickness=n, max_element_size=h_max, grading=grading, curvature=curvature,
                     epsilon_abs=eps * diagonal, surface_tolerance=tol, project=project, morph=morph,
                     n_surface_triangles=int(len(faces)), n_background_tets=int(len(background[1]))),
        timings=timings, **measured)
    return mesh, report
