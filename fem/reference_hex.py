"""An independent reference for notch-hinge compliances: 27-node (triquadratic Lagrange)
hexahedra on the exact geometry.

What it shares with the mapped P2-tet meshes it checks (``flexcal.fem.mesh_mapped``) is
only the problem: the part (``CircularNotchHinge``), the material, the clamped fixed face
and the free face rigidly tied to its centre. Everything that makes a discretisation is
its own, written here (of ``flexcal.fem`` it imports only the linear solver):

* element family: Q2 hexahedra (27 nodes, 3 x 3 x 3 tensor-product Lagrange on
  [-1, 1]^3), not 10-node tets; Gauss-Legendre quadrature (4 x 4 x 3 points);
* geometry: isoparametric Q2 on a map of the parent box (x, eta, z), eta in [-1/2, 1/2]:
  (x, eta, z) -> (x, eta h_I(x), z), h_I the quadratic interpolant of the exact notch height
  h(x) at the cell's three x nodes (every node on the exact surfaces; rigid motions and
  linear fields exact). The exact map itself would not do: dh/dx is unbounded where the arc
  turns vertical and the parent-space polynomials then cannot follow a smooth field
  (measured: a rigid rotation kept 11 % of mu V of energy, and C_rz,Mz came out 50x stiff);
* grid: x lines uniform in the arc angle of the notch where the profile turns and graded
  with the local height at the neck, cosine spacing in the blocks, across the height and the
  width (fine at every surface and end face; ``reference_grid``), its own counts;
  refinement divides the grid's parameters r times (nested);
* assembly (scipy COO), end conditions (its own elimination of the tied face: u_s =
  u_m + theta x (x_s - x_m)) and condensation onto the free reference point.

Only the sparse direct solve is shared (``flexcal.fem.solve.solve_spd``: PARDISO, else
SuperLU): it is exact to round-off and discretises nothing.

Hinge frame as in ``flexcal.geometry.params``; SI. DOF order ux, uy, uz, rx, ry, rz;
compliance rows displacements, columns loads Fx, Fy, Fz, Mx, My, Mz at the free face centre.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from flexcal.geometry.params import STEEL, Material

from .solve import solve_spd

__all__ = ["reference_grid", "hex27_hinge_compliance"]

# 1-D quadratic Lagrange on [-1, 1], nodes -1, 0, 1
_NODES_1D = np.array([-1.0, 0.0, 1.0])


def _lagrange_1d(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives (len(s), 3) of the three quadratic Lagrange functions."""
    s = np.asarray(s, float)[:, None]
    value = np.hstack([0.5 * s * (s - 1.0), 1.0 - s * s, 0.5 * s * (s + 1.0)])
    slope = np.hstack([s - 0.5, -2.0 * s, s + 0.5])
    return value, slope


def _notch_profile(hinge, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """h(x) [m] and dh/dx [-] of the circular notch (exact, its own formula)."""
    R, t = hinge.radius, hinge.thickness
    x = np.asarray(x, float)
    inside = np.abs(x) < R
    root = np.sqrt(np.clip(R * R - x * x, 0.0, None))
    h = np.where(inside, t + 2.0 * R - 2.0 * root, t + 2.0 * R)
    with np.errstate(divide="ignore", invalid="ignore"):
        dh = np.where(inside, 2.0 * x / np.where(inside, root, 1.0), 0.0)
    return h, dh


def reference_grid(hinge, n_through: int = 1, *, aspect: float = 3.0, n_arc: int = 4,
                   width_cells: int | None = None, refinement: int = 1
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell boundaries (x [m], eta [-], z [m]) of the reference grid of a circular notch hinge.

    x: over the notch, cells uniform in a parameter s whose density along the arc angle phi
    (x = R sin phi) is the larger of n_through R cos phi / (aspect h) (cells ``aspect``
    local heights long / n_through) and 2 n_arc / pi (n_arc cells per quarter arc where the
    profile turns); lines at 0 and +-R; each block in ceil(block / (height / n_through))
    cells with cosine spacing, at least 2. eta: n_through cells with cosine spacing. z:
    ``width_cells`` (default ceil(b / (aspect t / n_through)), at least 2, even) cells with
    cosine spacing. (Cosine: fine at the surfaces and the end faces, whose rims are the
    singular lines of the clamped and tied faces.)
    ``refinement`` r divides each of these parameters (s, eta, the cosine angle of z, x in
    the blocks) r times finer: nested grids, cell size 1 / r in parameter space.
    """
    R, t, b, block = hinge.radius, hinge.thickness, hinge.width, hinge.block_length
    n, r = int(n_through), int(refinement)
    if n < 1 or r < 1:
        raise ValueError("n_through and refinement must be >= 1")
    phi = np.linspace(0.0, 0.5 * np.pi, 20001)
    x = R * np.sin(phi)
    h, _ = _notch_profile(hinge, x)
    density = np.maximum(n * R * np.cos(phi) / (aspect * h), 2.0 * n_arc / np.pi)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(phi))])
    n_half = max(1, math.ceil(s[-1]))
    # refinement divides the parameter s (not x): nested, and the cells keep shrinking
    # like phi^2 where the arc turns vertical (x cut evenly there would leave the
    # quadratic geometry a square-root profile to follow in the last cell)
    half = np.interp(np.linspace(0.0, s[-1], r * n_half + 1), s, x)
    half[0], half[-1] = 0.0, R
    n_block = max(2, math.ceil(block / ((t + 2.0 * R) / n)))
    # cosine spacing: fine at the block's ends (where the arc ends, and at the tied end face
    # whose rims are singular lines of the clamped/tied boundary)
    blocks = R + 0.5 * block * (1.0 - np.cos(np.linspace(0.0, np.pi, r * n_block + 1)))[1:]
    blocks[-1] = R + block
    x_lines = np.concatenate([-blocks[::-1], -half[::-1], half[1:], blocks])
    nz = width_cells if width_cells is not None else max(2, math.ceil(b / (aspect * t / n)))
    nz += nz % 2
    z_lines = -0.5 * b * np.cos(np.linspace(0.0, np.pi, r * nz + 1))
    z_lines[0], z_lines[-1], z_lines[r * nz // 2] = -0.5 * b, 0.5 * b, 0.0
    # eta: cosine spacing too (fine at the surfaces: the bending stresses at the neck, the
    # rims of the end faces on the blocks); n r even keeps the neutral line eta = 0
    eta_lines = -0.5 * np.cos(np.linspace(0.0, np.pi, r * n + 1))
    eta_lines[0], eta_lines[-1] = -0.5, 0.5
    if (r * n) % 2 == 0:
        eta_lines[r * n // 2] = 0.0
    return x_lines, eta_lines, z_lines


def _column_matrices(hinge, x_lines: np.ndarray, eta_lines: np.ndarray, material: Material
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Element stiffness of every (x, eta) cell for a unit cell depth dz = 1 m, split by
    how it scales with dz: K(dz) = dz A + B + C / dz, each (n_x, n_eta, 81, 81).
    (A: x/y-gradient products, B: mixed with the z-gradient, C: z-gradient products; the
    physical z-gradient is (2 / dz) d/dzeta and det J carries dz / 2.)"""
    E, nu = material.youngs_modulus, material.poisson_ratio
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    gx, wx = np.polynomial.legendre.leggauss(4)
    gz, wz = np.polynomial.legendre.leggauss(3)
    vx, dx1 = _lagrange_1d(gx)
    vz, dz1 = _lagrange_1d(gz)
    # shape gradients in local coords at (qx, qe, qz), node (a, b, c): (4, 4, 3, 27, 3)
    dN = np.zeros((4, 4, 3, 3, 3, 3, 3))
    dN[..., 0] = np.einsum("ia,jb,kc->ijkabc", dx1, vx, vz)
    dN[..., 1] = np.einsum("ia,jb,kc->ijkabc", vx, dx1, vz)
    dN[..., 2] = np.einsum("ia,jb,kc->ijkabc", vx, vx, dz1)
    dN = dN.reshape(4, 4, 3, 27, 3)
    weights = np.einsum("i,j,k->ijk", wx, wx, wz)
    x0, x1 = x_lines[:-1], x_lines[1:]
    e0, e1 = eta_lines[:-1], eta_lines[1:]
    lx, le = x1 - x0, e1 - e0
    xq = 0.5 * (x0 + x1)[:, None] + 0.5 * lx[:, None] * gx[None, :]  # (n_x, 4)
    eq = 0.5 * (e0 + e1)[:, None] + 0.5 * le[:, None] * gx[None, :]  # (n_eta, 4)
    # isoparametric geometry: h at the cell's three x nodes, interpolated by the same
    # quadratics as the displacement (y = eta h_I(x) is then in the Q2 space, so rigid motions
    # and linear fields are exact; the exact map's dh/dx is unbounded where the arc turns
    # vertical, and e h(x) would not be, measured: a rigid rotation kept 11 % of mu V)
    h_nodes = np.stack([_notch_profile(hinge, x)[0] for x in (x0, 0.5 * (x0 + x1), x1)], axis=1)  # (n_x, 3)
    h = h_nodes @ vx.T
    dh = (h_nodes @ dx1.T) * (2.0 / lx)[:, None]
    nx_, ne_ = lx.size, le.size
    # parent gradients (d/dx, d/deta, d/dz at dz = 1) then physical
    gpx = dN[None, None, ..., 0] * (2.0 / lx)[:, None, None, None, None, None]
    gpe = dN[None, None, ..., 1] * (2.0 / le)[None, :, None, None, None, None]
    gpz = dN[None, None, ..., 2] * 2.0
    gpx = np.broadcast_to(gpx, (nx_, ne_, 4, 4, 3, 27))
    gpe = np.broadcast_to(gpe, (nx_, ne_, 4, 4, 3, 27))
    gpz = np.broadcast_to(gpz, (nx_, ne_, 4, 4, 3, 27))
    hq = h[:, None, :, None, None, None]
    slope = (eq[None, :, None, :, None, None] * dh[:, None, :, None, None, None]) / hq
    G = np.empty((nx_, ne_, 4, 4, 3, 27, 3))
    G[..., 0] = gpx - slope * gpe
    G[..., 1] = gpe / hq
    G[..., 2] = gpz
    det = (h[:, None, :, None, None] * (0.5 * lx)[:, None, None, None, None]
           * (0.5 * le)[None, :, None, None, None] * 0.5)  # dz = 1
    wdet = det * weights[None, None]  # (n_x, n_eta, 4, 4, 3)
    G = G.reshape(nx_ * ne_, 48, 27, 3)
    wdet = np.broadcast_to(wdet, (nx_, ne_, 4, 4, 3)).reshape(nx_ * ne_, 48)
    out = []
    masks = ({(0, 0), (0, 1), (1, 0), (1, 1)}, {(0, 2), (1, 2), (2, 0), (2, 1)}, {(2, 2)})
    Gw = G * np.sqrt(wdet)[:, :, None, None]
    flat = Gw.reshape(nx_ * ne_, 48, 81)
    M = np.matmul(flat.transpose(0, 2, 1), flat).reshape(-1, 27, 3, 27, 3)  # sum_q w G_ai G_bj
    for mask in masks:
        Mm = np.zeros_like(M)
        for i, j in mask:
            Mm[:, :, i, :, j] = M[:, :, i, :, j]
        K = lam * Mm + mu * Mm.transpose(0, 1, 4, 3, 2)
        # mu delta_ij sum_k M[a, k, b, k]: only the k-terms of this scaling class
        trace = sum(Mm[:, :, k, :, k] for k in range(3))
        for i in range(3):
            K[:, :, i, :, i] += mu * trace
        out.append(K.reshape(nx_, ne_, 81, 81))
    return tuple(out)


def _stiffness(hinge, lines, material: Material) -> tuple[sp.csr_matrix, np.ndarray]:
    """Global stiffness (3 n, 3 n) CSR and node coordinates (n, 3) [m] of the grid."""
    x_lines, eta_lines, z_lines = lines
    A, B, C = _column_matrices(hinge, x_lines, eta_lines, material)
    nx_, ne_, nz_ = x_lines.size - 1, eta_lines.size - 1, z_lines.size - 1
    shape = (2 * nx_ + 1, 2 * ne_ + 1, 2 * nz_ + 1)
    fine = []
    for lines in (x_lines, eta_lines, z_lines):
        f = np.empty(2 * lines.size - 1)
        f[0::2], f[1::2] = lines, 0.5 * (lines[:-1] + lines[1:])
        fine.append(f)
    X, Eta, Z = np.meshgrid(*fine, indexing="ij")
    h, _ = _notch_profile(hinge, X.ravel())
    nodes = np.column_stack([X.ravel(), Eta.ravel() * h, Z.ravel()])
    local = np.stack(np.meshgrid(np.arange(3), np.arange(3), np.arange(3), indexing="ij"), -1).reshape(27, 3)
    ix, ie = np.meshgrid(np.arange(nx_), np.arange(ne_), indexing="ij")
    total = sp.csr_matrix((3 * nodes.shape[0],) * 2)
    dz = np.diff(z_lines)
    for k in range(nz_):
        idx = np.stack([2 * ix[..., None] + local[:, 0], 2 * ie[..., None] + local[:, 1],
                        np.full((nx_, ne_, 27), 2 * k) + local[:, 2]], 0)
        node = np.ravel_multi_index(tuple(idx), shape).reshape(nx_ * ne_, 27)
        dof = (3 * node[:, :, None] + np.arange(3)).reshape(-1, 81)
        Ke = (dz[k] * A + B + C / dz[k]).reshape(-1, 81, 81)
        rows = np.repeat(dof, 81, axis=1).ravel()
        cols = np.tile(dof, (1, 81)).ravel()
        total = total + sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=total.shape)
    return total.tocsr(), nodes


def hex27_hinge_compliance(hinge, *, n_through: int = 1, refinement: int = 1, material: Material = STEEL,
                           **grid_options) -> tuple[np.ndarray, int]:
    """(compliance (6, 6) [SI] at the free face centre with the fixed face clamped, number
    of unknowns) of a circular notch hinge on the Q2 reference grid
    (``reference_grid(hinge, n_through, refinement=refinement, **grid_options)``)."""
    lines = reference_grid(hinge, n_through, refinement=refinement, **grid_options)
    K, nodes = _stiffness(hinge, lines, material)
    x = nodes[:, 0]
    length = lines[0][-1]
    fixed = np.flatnonzero(np.isclose(x, lines[0][0], rtol=0.0, atol=1e-12))
    free = np.flatnonzero(np.isclose(x, length, rtol=0.0, atol=1e-12))
    point = np.array([length, 0.0, 0.0])
    n_dof = K.shape[0]
    slave = (3 * free[:, None] + np.arange(3)).ravel()
    clamped = (3 * fixed[:, None] + np.arange(3)).ravel()
    interior = np.setdiff1d(np.arange(n_dof), np.concatenate([slave, clamped]))
    # u_s = u_m + theta x (x_s - x_m) = [I, -skew(x_s - x_m)] (u_m, theta)
    d = nodes[free] - point
    T = np.zeros((free.size, 3, 6))
    T[:, :, :3] = np.eye(3)
    T[:, 0, 4], T[:, 0, 5] = d[:, 2], -d[:, 1]
    T[:, 1, 3], T[:, 1, 5] = -d[:, 2], d[:, 0]
    T[:, 2, 3], T[:, 2, 4] = d[:, 1], -d[:, 0]
    T = T.reshape(-1, 6)
    K_ii = K[interior][:, interior].tocsr()
    K_is = K[interior][:, slave]
    K_im = np.asarray((K_is @ T))
    K_mm = T.T @ (K[slave][:, slave] @ T)
    X = solve_spd(K_ii, K_im)  # K_ii^-1 K_im
    K_c = K_mm - K_im.T @ X
    K_c = 0.5 * (K_c + K_c.T)
    return np.linalg.inv(K_c), interior.size + 6
