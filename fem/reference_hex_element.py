"""The element, assembly and end conditions of the independent Q2-hexahedron references
(``flexcal.fem.reference_hex`` for notch hinges, ``flexcal.fem.reference_hex_chain`` for
chain segments); each part supplies only its geometry and grid (a ``HexGrid``).

* element: 27-node (triquadratic Lagrange) hexahedra on [-1, 1]^3, Gauss-Legendre
  quadrature 4 x 4 x 3 points;
* geometry: a tensor grid of parent lines (x, p, z) [m] with the cells inside the part
  active; the map is (x, p, z) -> (x, p g_I(x), z) in the core |p| <= ``core_half`` and the
  identity outside it, g_I the quadratic interpolant of the part's scale g(x) at each cell's
  three x nodes (isoparametric: every node on the exact surfaces, rigid motions and linear
  fields exact; the exact g has an unbounded slope where a notch or fillet turns vertical);
* assembly (scipy, upper triangle only, node order: interior, then each tied face), the
  elimination of rigidly tied faces (u_s = u_m + theta x (x_s - x_m)) and the condensation
  onto their reference points.

Only the sparse direct solve is shared with the P2-tet code (``flexcal.fem.solve.solve_spd``:
PARDISO, else SuperLU; exact to round-off, it discretises nothing). SI; DOF order ux, uy,
uz, rx, ry, rz per reference point.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from flexcal.geometry.params import Material

from .solve import solve_spd

__all__ = ["HexGrid", "grid_nodes", "grid_stiffness", "full_stiffness", "tied_stiffness"]

_GAUSS_XP = np.polynomial.legendre.leggauss(4)
_GAUSS_Z = np.polynomial.legendre.leggauss(3)
# local node (a, b, c) of the 27, a along x, b along p, c along z
_LOCAL = np.stack(np.meshgrid(np.arange(3), np.arange(3), np.arange(3), indexing="ij"), -1).reshape(27, 3)


@dataclass(frozen=True, kw_only=True, eq=False)
class HexGrid:
    """Parent grid of a Q2-hex reference: lines x, p, z [m] (p: the parent of y), active
    (n_x, n_p, n_z) bool (the cells inside the part), and the map y = p scale(x) for
    |p| <= core_half [m], y = p elsewhere (scale: x [m] -> [-], exact, vectorised)."""

    x: np.ndarray
    p: np.ndarray
    z: np.ndarray
    active: np.ndarray
    core_half: float
    scale: Callable[[np.ndarray], np.ndarray]

    def __post_init__(self):
        if self.active.shape != (self.x.size - 1, self.p.size - 1, self.z.size - 1):
            raise ValueError(f"active has shape {self.active.shape}; the lines make "
                             f"{(self.x.size - 1, self.p.size - 1, self.z.size - 1)} cells")

    def in_core(self, p: np.ndarray) -> np.ndarray:
        return np.abs(p) <= self.core_half * (1.0 + 1e-12)


def lagrange_1d(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives (len(s), 3) of the quadratic Lagrange functions, nodes -1, 0, 1."""
    s = np.asarray(s, float)[:, None]
    value = np.hstack([0.5 * s * (s - 1.0), 1.0 - s * s, 0.5 * s * (s + 1.0)])
    slope = np.hstack([s - 0.5, -2.0 * s, s + 0.5])
    return value, slope


def _fine(lines: np.ndarray) -> np.ndarray:
    """Node lines of a Q2 grid: the cell lines and their midpoints."""
    out = np.empty(2 * lines.size - 1)
    out[0::2], out[1::2] = lines, 0.5 * (lines[:-1] + lines[1:])
    return out


def _used_nodes(grid: HexGrid) -> np.ndarray:
    """Bool (2 n_x + 1, 2 n_p + 1, 2 n_z + 1): the nodes of the active cells."""
    shape = tuple(2 * s + 1 for s in grid.active.shape)
    used = np.zeros(shape, bool)
    cells = np.argwhere(grid.active)
    for a, b, c in _LOCAL:
        used[2 * cells[:, 0] + a, 2 * cells[:, 1] + b, 2 * cells[:, 2] + c] = True
    return used


def grid_nodes(grid: HexGrid) -> tuple[np.ndarray, np.ndarray]:
    """(node coordinates (n, 3) [m] of the active cells' nodes, full-grid index (n,) in
    C order of the (2 n_x + 1, 2 n_p + 1, 2 n_z + 1) node grid)."""
    used = _used_nodes(grid)
    index = np.flatnonzero(used)
    i, j, k = np.unravel_index(index, used.shape)
    x, p, z = _fine(grid.x)[i], _fine(grid.p)[j], _fine(grid.z)[k]
    y = np.where(grid.in_core(p), p * grid.scale(x), p)
    return np.column_stack([x, y, z]), index


def _cell_matrices(grid: HexGrid, cells_x: np.ndarray, material: Material
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Element stiffness of the (x, p) cells cells_x x all p for a unit depth dz = 1 m,
    split by how it scales with dz: K(dz) = dz A + B + C / dz, each (len(cells_x), n_p, 81, 81).
    (A: x/y-gradient products, B: mixed with the z-gradient, C: z-gradient products; the
    physical z-gradient is (2 / dz) d/dzeta and det J carries dz / 2.)"""
    E, nu = material.youngs_modulus, material.poisson_ratio
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    gx, wx = _GAUSS_XP
    gz, wz = _GAUSS_Z
    vx, dx1 = lagrange_1d(gx)
    vz, dz1 = lagrange_1d(gz)
    # shape gradients in local coords at (qx, qp, qz), node (a, b, c): (4, 4, 3, 27, 3)
    dN = np.zeros((4, 4, 3, 3, 3, 3, 3))
    dN[..., 0] = np.einsum("ia,jb,kc->ijkabc", dx1, vx, vz)
    dN[..., 1] = np.einsum("ia,jb,kc->ijkabc", vx, dx1, vz)
    dN[..., 2] = np.einsum("ia,jb,kc->ijkabc", vx, vx, dz1)
    dN = dN.reshape(4, 4, 3, 27, 3)
    weights = np.einsum("i,j,k->ijk", wx, wx, wz)
    x0, x1 = grid.x[cells_x], grid.x[cells_x + 1]
    p0, p1 = grid.p[:-1], grid.p[1:]
    lx, lp = x1 - x0, p1 - p0
    pq = 0.5 * (p0 + p1)[:, None] + 0.5 * lp[:, None] * gx[None, :]  # (n_p, 4)
    # isoparametric geometry: the scale at the cell's three x nodes, interpolated by the same
    # quadratics as the displacement (y = p g_I(x) is then in the Q2 space: rigid motions and
    # linear fields exact); cells outside the core: g = 1
    g_nodes = np.stack([grid.scale(x) for x in (x0, 0.5 * (x0 + x1), x1)], axis=1)  # (n_x, 3)
    core = grid.in_core(0.5 * (p0 + p1))  # (n_p,)
    g = np.where(core[None, :, None], (g_nodes @ vx.T)[:, None, :], 1.0)  # (n_x, n_p, 4)
    dg = np.where(core[None, :, None], ((g_nodes @ dx1.T) * (2.0 / lx)[:, None])[:, None, :], 0.0)
    nx_, np_ = lx.size, lp.size
    gpx = dN[None, None, ..., 0] * (2.0 / lx)[:, None, None, None, None, None]
    gpp = dN[None, None, ..., 1] * (2.0 / lp)[None, :, None, None, None, None]
    gpz = dN[None, None, ..., 2] * 2.0
    gq = g[:, :, :, None, None, None]
    slope = pq[None, :, None, :, None, None] * dg[:, :, :, None, None, None] / gq
    G = np.empty((nx_, np_, 4, 4, 3, 27, 3))
    G[..., 0] = gpx - slope * gpp
    G[..., 1] = gpp / gq
    G[..., 2] = gpz
    det = (g[:, :, :, None, None] * (0.5 * lx)[:, None, None, None, None]
           * (0.5 * lp)[None, :, None, None, None] * 0.5)  # dz = 1
    wdet = det * weights[None, None]  # (n_x, n_p, 4, 4, 3)
    G = G.reshape(nx_ * np_, 48, 27, 3)
    Gw = G * np.sqrt(wdet.reshape(nx_ * np_, 48))[:, :, None, None]
    flat = Gw.reshape(nx_ * np_, 48, 81)
    M = np.matmul(flat.transpose(0, 2, 1), flat).reshape(-1, 27, 3, 27, 3)  # sum_q w G_ai G_bj
    out = []
    masks = ({(0, 0), (0, 1), (1, 0), (1, 1)}, {(0, 2), (1, 2), (2, 0), (2, 1)}, {(2, 2)})
    for mask in masks:
        Mm = np.zeros_like(M)
        for i, j in mask:
            Mm[:, :, i, :, j] = M[:, :, i, :, j]
        K = lam * Mm + mu * Mm.transpose(0, 1, 4, 3, 2)
        # mu delta_ij sum_k M[a, k, b, k]: only the k-terms of this scaling class
        trace = sum(Mm[:, :, k, :, k] for k in range(3))
        for i in range(3):
            K[:, :, i, :, i] += mu * trace
        out.append(K.reshape(nx_, np_, 81, 81))
    return tuple(out)


def _sum_tree(parts: list[sp.csr_matrix]) -> sp.csr_matrix:
    """Sum of sparse matrices pairwise (work ~ nnz log(len) instead of nnz len)."""
    while len(parts) > 1:
        parts = [parts[i] + parts[i + 1] if i + 1 < len(parts) else parts[i] for i in range(0, len(parts), 2)]
    return parts[0]


def grid_stiffness(grid: HexGrid, material: Material, order: np.ndarray, *, chunk_cells: int = 400
                   ) -> sp.csr_matrix:
    """Upper triangle (3 n, 3 n) CSR of the global stiffness [SI] of the active cells, DOF
    3 order[node] + component for the full-grid node index (``grid_nodes``'s second value;
    ``order``: full-grid node index -> new node number, -1 for unused nodes).
    ``chunk_cells``: (x, p) cells per kernel batch (memory ~ 0.5 MB a cell)."""
    nx_, np_, nz_ = grid.active.shape
    shape = (2 * nx_ + 1, 2 * np_ + 1, 2 * nz_ + 1)
    n_dof = 3 * int(order.max() + 1)
    dz = np.diff(grid.z)
    per_chunk = max(1, chunk_cells // np_)
    parts = []
    for start in range(0, nx_, per_chunk):
        cells_x = np.arange(start, min(nx_, start + per_chunk))
        if not grid.active[cells_x].any():
            continue
        A, B, C = _cell_matrices(grid, cells_x, material)
        rows_all, cols_all, vals_all = [], [], []
        for k in range(nz_):
            ci, cj = np.nonzero(grid.active[cells_x, :, k])
            if ci.size == 0:
                continue
            gi = cells_x[ci]
            node = np.ravel_multi_index((2 * gi[:, None] + _LOCAL[:, 0], 2 * cj[:, None] + _LOCAL[:, 1],
                                         2 * k + _LOCAL[:, 2][None, :].repeat(ci.size, 0)), shape)
            dof = (3 * order[node][:, :, None] + np.arange(3)).reshape(-1, 81)
            Ke = dz[k] * A[ci, cj] + B[ci, cj] + C[ci, cj] / dz[k]
            rows = np.broadcast_to(dof[:, :, None], Ke.shape)
            cols = np.broadcast_to(dof[:, None, :], Ke.shape)
            upper = rows <= cols
            rows_all.append(rows[upper])
            cols_all.append(cols[upper])
            vals_all.append(Ke[upper])
        parts.append(sp.csr_matrix((np.concatenate(vals_all), (np.concatenate(rows_all), np.concatenate(cols_all))),
                                   shape=(n_dof, n_dof)))
        del A, B, C
    return _sum_tree(parts)


def full_stiffness(grid: HexGrid, material: Material) -> tuple[sp.csr_matrix, np.ndarray]:
    """(symmetric global stiffness (3 n, 3 n) CSR [SI], node coordinates (n, 3) [m]) of the
    active cells, nodes in ``grid_nodes``'s order (for checks: rigid motions, volumes)."""
    nodes, index = grid_nodes(grid)
    order = np.full(int(np.prod([2 * s + 1 for s in grid.active.shape])), -1, np.int64)
    order[index] = np.arange(index.size)
    upper = grid_stiffness(grid, material, order)
    return (upper + sp.triu(upper, 1).T).tocsr(), nodes


def _tie_transform(nodes: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(3 len(nodes), 6): u_s = u_m + theta x (x_s - x_m) = [I, -skew(x_s - x_m)] (u_m, theta)."""
    d = nodes - point
    T = np.zeros((nodes.shape[0], 3, 6))
    T[:, :, :3] = np.eye(3)
    T[:, 0, 4], T[:, 0, 5] = d[:, 2], -d[:, 1]
    T[:, 1, 3], T[:, 1, 5] = -d[:, 2], d[:, 0]
    T[:, 2, 3], T[:, 2, 4] = d[:, 1], -d[:, 0]
    return T.reshape(-1, 6)


def tied_stiffness(grid: HexGrid, material: Material, ties: list[tuple[np.ndarray, np.ndarray]],
                   clamped: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """(condensed stiffness (6 m, 6 m) [SI] at the m reference points, number of unknowns):
    ties [(node mask (n,) over ``grid_nodes``, reference point (3,) [m])]: each face rigidly
    tied to its point; clamped: node mask of the clamped nodes (None: none)."""
    nodes, index = grid_nodes(grid)
    n = nodes.shape[0]
    groups = [np.zeros(n, bool) if clamped is None else np.asarray(clamped, bool)]
    groups += [np.asarray(mask, bool) for mask, _ in ties]
    if np.any(np.sum(groups, axis=0) > 1):
        raise ValueError("a node is in two tied or clamped faces")
    interior = np.flatnonzero(~np.any(groups, axis=0))
    faces = [np.flatnonzero(m) for m in groups[1:]]
    # new number -> node: interior, each tied face, the clamped nodes last (dropped below)
    sequence = np.concatenate([interior, *faces, np.flatnonzero(groups[0])])
    order = np.full(int(np.prod([2 * s + 1 for s in grid.active.shape])), -1, np.int64)
    order[index[sequence]] = np.arange(n)
    upper = grid_stiffness(grid, material, order)
    n_i = 3 * interior.size
    T = sp.block_diag([_tie_transform(nodes[f], np.asarray(pt, float)) for f, (_, pt) in zip(faces, ties)]).tocsr()
    n_s = T.shape[0]
    K_ii = upper[:n_i][:, :n_i]
    K_is = upper[:n_i][:, n_i:n_i + n_s]  # interior numbered first: K_is lies in the upper triangle
    K_ss = upper[n_i:n_i + n_s][:, n_i:n_i + n_s]
    K_ss = K_ss + sp.triu(K_ss, 1).T
    K_im = np.asarray((K_is @ T).todense())
    K_mm = np.asarray((T.T @ (K_ss @ T)).todense())
    del upper, K_is, K_ss
    X = solve_spd(K_ii, K_im, upper_triangle=True)  # K_ii^-1 K_im
    K_c = K_mm - K_im.T @ X
    return 0.5 * (K_c + K_c.T), n_i + 6 * len(ties)
