"""Structured quadratic-tet meshes of boxes, beams and mapped notch hinges.

For tests, the cantilever study and benchmarks (the general mesher for CadQuery solids
is ``flexcal.fem.mesh``). Each hexahedral cell of a tensor grid is split into the six
Kuhn tets around its main diagonal; every cell uses the same split, so the faces match
and the mesh is conforming. Mid-edge nodes come from a grid with twice the resolution,
so a node shared by neighbouring tets is one node.

``notch_hinge_tet_mesh`` maps such a grid onto a right-circular notch hinge by scaling
y with the local height; mapping the mid-edge nodes too puts them on the true circular
profile (curved, isoparametric tets).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from flexcal.geometry.params import CircularNotchHinge

__all__ = ["StructuredTetMesh", "grid_tet_mesh", "box_tet_mesh", "notch_hinge_tet_mesh", "notch_height"]


@dataclass(frozen=True, kw_only=True, eq=False)
class StructuredTetMesh:
    """Quadratic tet mesh: nodes (n_nodes, 3) [m], tets (n_tets, 10) int in VTK order
    (corners 0-3, mid-edges 01, 12, 02, 03, 13, 23), positive volumes. Same fields as
    ``flexcal.fem.mesh.TetMesh``."""

    nodes: np.ndarray
    tets: np.ndarray

    def __post_init__(self) -> None:
        if self.nodes.ndim != 2 or self.nodes.shape[1] != 3:
            raise ValueError(f"nodes has shape {self.nodes.shape}; expected (n_nodes, 3)")
        if self.tets.ndim != 2 or self.tets.shape[1] != 10:
            raise ValueError(f"tets has shape {self.tets.shape}; expected (n_tets, 10)")


# The six Kuhn tets of the unit cube: a path from (0,0,0) to (1,1,1) along the axes in
# the order given by each permutation. Corner offsets in units of a cell.
def _kuhn_tets() -> np.ndarray:
    tets = []
    for perm in itertools.permutations(range(3)):
        corner = np.zeros(3, int)
        path = [corner.copy()]
        for axis in perm:
            corner[axis] += 1
            path.append(corner.copy())
        path = np.array(path)
        # odd permutations give negative volume: swap corners 1 and 2
        if np.linalg.det(path[1:] - path[0]) < 0:
            path[[1, 2]] = path[[2, 1]]
        tets.append(path)
    return np.array(tets)  # (6, 4, 3)


_KUHN = _kuhn_tets()
_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])


def _check_coordinates(name: str, values: np.ndarray) -> np.ndarray:
    values = np.asarray(values, float)
    if values.ndim != 1 or values.size < 2:
        raise ValueError(f"{name} needs at least 2 grid coordinates, got shape {values.shape}")
    if not np.all(np.diff(values) > 0):
        raise ValueError(f"{name} grid coordinates must be strictly increasing")
    return values


def grid_tet_mesh(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> StructuredTetMesh:
    """P2 tet mesh of the tensor grid with corner coordinates x (n_x + 1,), y, z [m]
    (strictly increasing, may be graded). 6 * n_x * n_y * n_z tets; straight edges."""
    axes = [_check_coordinates(n, v) for n, v in (("x", x), ("y", y), ("z", z))]
    counts = np.array([a.size - 1 for a in axes])
    # fine grid: corners at even indices, midpoints at odd
    fine = [np.empty(2 * a.size - 1) for a in axes]
    for f, a in zip(fine, axes):
        f[0::2] = a
        f[1::2] = 0.5 * (a[:-1] + a[1:])
    shape = np.array([f.size for f in fine])
    X, Y, Z = np.meshgrid(*fine, indexing="ij")
    nodes = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])

    cells = np.stack(np.meshgrid(*[np.arange(n) for n in counts], indexing="ij"), axis=-1).reshape(-1, 3)
    corners = 2 * (cells[:, None, None, :] + _KUHN[None])  # (cells, 6, 4, 3) fine indices
    corners = corners.reshape(-1, 4, 3)
    mids = (corners[:, _EDGES[:, 0]] + corners[:, _EDGES[:, 1]]) // 2
    fine_index = np.concatenate([corners, mids], axis=1)  # (tets, 10, 3)
    tets = np.ravel_multi_index((fine_index[..., 0], fine_index[..., 1], fine_index[..., 2]), tuple(shape))
    return StructuredTetMesh(nodes=nodes, tets=tets.astype(np.int64))


def box_tet_mesh(
    lx: float, ly: float, lz: float, nx: int, ny: int, nz: int, *, origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> StructuredTetMesh:
    """P2 tet mesh of the box [0, lx] x [0, ly] x [0, lz] [m] shifted by ``origin`` [m],
    with nx * ny * nz cells of 6 tets each."""
    for name, length in (("lx", lx), ("ly", ly), ("lz", lz)):
        if not length > 0:
            raise ValueError(f"{name}={length} m must be > 0")
    for name, n in (("nx", nx), ("ny", ny), ("nz", nz)):
        if int(n) != n or n < 1:
            raise ValueError(f"{name}={n} must be a positive integer")
    return grid_tet_mesh(
        origin[0] + np.linspace(0.0, lx, int(nx) + 1),
        origin[1] + np.linspace(0.0, ly, int(ny) + 1),
        origin[2] + np.linspace(0.0, lz, int(nz) + 1),
    )


def notch_height(hinge: CircularNotchHinge, x: np.ndarray) -> np.ndarray:
    """Height h(x) [m] of a circular notch hinge at x [m] (hinge frame, x = 0 at the
    thinnest section): t + 2R - 2 sqrt(R^2 - x^2) inside the notch, t + 2R outside."""
    x = np.asarray(x, float)
    R, t = hinge.radius, hinge.thickness
    inside = np.abs(x) < R
    return np.where(inside, t + 2.0 * R - 2.0 * np.sqrt(np.clip(R * R - x * x, 0.0, None)), t + 2.0 * R)


def _graded_notch_x(hinge: CircularNotchHinge, n_thickness: int, aspect: float, n_arc: int, refinement: int) -> np.ndarray:
    """x grid [m] over [-R, R], symmetric, with nodes at 0 and +-R. The spacing is the
    smaller of ``aspect * h(x) / n_thickness`` (cells keep their shape as the section
    thickens) and the length of ``1 / n_arc`` of a quarter of the notch circle (the
    profile is resolved where it turns vertical, |x| -> R). ``refinement`` splits every
    cell into that many (nested grids)."""
    R = hinge.radius
    phi = np.linspace(0.0, 0.5 * np.pi, 8001)  # x = R sin(phi): fine where the arc turns
    x = R * np.sin(phi)
    # cells per unit phi: from the thickness rule (dx/dphi = R cos phi) and the arc rule
    density = np.maximum(n_thickness * R * np.cos(phi) / (aspect * notch_height(hinge, x)), 2.0 * n_arc / np.pi)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(phi))])
    n_half = max(1, math.ceil(s[-1])) * refinement
    half = np.interp(np.linspace(0.0, s[-1], n_half + 1), s, x)
    half[-1] = R
    return np.concatenate([-half[::-1], half[1:]])


def notch_hinge_tet_mesh(
    hinge: CircularNotchHinge,
    n_thickness: int = 2,
    *,
    n_width: int | None = None,
    aspect: float = 2.0,
    n_arc: int = 8,
    n_block: int | None = None,
    curved: bool = True,
    refinement: int = 1,
) -> StructuredTetMesh:
    """Mapped P2 tet mesh of a right-circular notch hinge in the hinge frame.

    x along the hinge, x in [-(R + block_length), R + block_length] [m]; y across the
    thickness, |y| <= h(x) / 2 (``notch_height``); z along the width, |z| <= b / 2.
    ``n_thickness`` cells across the height everywhere (so across t at the neck);
    ``aspect``: cell length / local cell height in the notch; ``n_arc``: at least this
    many cells along each quarter of the notch circle; ``n_width`` cells across b
    (default: cells about as wide as ``aspect`` times the neck cell height, at least 2);
    ``n_block`` cells along each block (default: about square cells). ``refinement``
    splits every cell of that grid into refinement^3 (the meshes of refinement 1, 2, 3,
    ... are nested in the parent grid: a clean sequence for convergence studies).
    ``curved=True``
    maps the mid-edge nodes onto the circular profile (isoparametric tets); ``False``
    keeps every edge straight (a polygonal approximation of the notch). With
    ``curved=True`` the few tets whose curved map would fold (next to the blocks, where
    the profile turns vertical) keep straight edges.
    """
    if int(n_thickness) != n_thickness or n_thickness < 1:
        raise ValueError(f"n_thickness={n_thickness} must be a positive integer")
    if not aspect > 0:
        raise ValueError(f"aspect={aspect} must be > 0")
    if int(refinement) != refinement or refinement < 1:
        raise ValueError(f"refinement={refinement} must be a positive integer")
    r = int(refinement)
    R, t, b, block = hinge.radius, hinge.thickness, hinge.width, hinge.block_length
    H = hinge.height
    x_notch = _graded_notch_x(hinge, int(n_thickness), aspect, int(n_arc), r)
    if n_block is None:
        n_block = max(1, math.ceil(block / (H / n_thickness)))
    x_block = np.linspace(R, R + block, r * int(n_block) + 1)[1:]
    x = np.concatenate([-x_block[::-1], x_notch, x_block])
    if n_width is None:
        n_width = max(2, math.ceil(b / (aspect * t / n_thickness)))
    # parent grid: y is the fraction eta in [-1/2, 1/2] of the local height
    parent = grid_tet_mesh(
        x, np.linspace(-0.5, 0.5, r * int(n_thickness) + 1), np.linspace(-b / 2, b / 2, r * int(n_width) + 1)
    )
    nodes = parent.nodes.copy()
    nodes[:, 1] = parent.nodes[:, 1] * notch_height(hinge, parent.nodes[:, 0])
    tets = parent.tets
    if not curved:
        _straighten(nodes, tets, np.arange(len(tets)))
    else:
        # Where the profile turns steeply (|x| -> R, h ~ sqrt(R - |x|)) the curved map can
        # fold; those few tets (next to the blocks, where the part is thick and stiff) get
        # straight edges. Repeat: straightening a shared mid-node changes the neighbour.
        for _ in range(10):
            folded = _folded_tets(nodes, tets)
            if folded.size == 0:
                break
            _straighten(nodes, tets, folded)
        else:  # pragma: no cover - the straight mesh is always valid
            raise RuntimeError("could not unfold the mapped notch mesh; use curved=False")
    return StructuredTetMesh(nodes=nodes, tets=tets)


def _straighten(nodes: np.ndarray, tets: np.ndarray, which: np.ndarray) -> None:
    """Move the mid-edge nodes of tets ``which`` to their edges' midpoints (in place)."""
    t = tets[which]
    nodes[t[:, 4:]] = 0.5 * (nodes[t[:, _EDGES[:, 0]]] + nodes[t[:, _EDGES[:, 1]]])


def _folded_tets(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Indices of tets whose quadratic map has det J <= 0 at a node or at a point of the
    14-point rule (the points the stiffness integration uses)."""
    from .elements import REFERENCE_NODES, TET_14POINT, jacobians, shape_gradients

    points = np.vstack([REFERENCE_NODES, TET_14POINT.points])
    J = jacobians(nodes[tets], shape_gradients(points))
    # the 3 x 3 determinants in closed form (cofactors of the first row): np.linalg.det's
    # batched LU took 1.1 s of a cold table1 truth's 18 segment meshes (profiled, session 17);
    # only the sign is used, and det J >= 0.77 of its mean on the prototype's leaves
    det = (J[..., 0, 0] * (J[..., 1, 1] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 1])
           - J[..., 0, 1] * (J[..., 1, 0] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 0])
           + J[..., 0, 2] * (J[..., 1, 0] * J[..., 2, 1] - J[..., 1, 1] * J[..., 2, 0]))
    return np.flatnonzero((det <= 0.0).any(axis=1))
