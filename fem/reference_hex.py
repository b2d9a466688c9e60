"""An independent reference for notch-hinge compliances: 27-node (triquadratic Lagrange)
hexahedra on the exact geometry.

What it shares with the mapped P2-tet meshes it checks (``flexcal.fem.mesh_mapped``) is
only the problem: the part (``CircularNotchHinge``), the material, the clamped fixed face
and the free face rigidly tied to its centre. Everything that makes a discretisation is
its own, written here (of ``flexcal.fem`` it imports only the linear solver):

* element family: Q2 hexahedra (27 nodes, 3 x 3 x 3 tensor-product Lagrange on
  [-1, 1]^3), not 10-node tets; Gauss-Legendre quadrature (4 x 4 x 3 points)
  (``flexcal.fem.reference_hex_element``, shared with the chain segments' reference);
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
* assembly (scipy, ``reference_hex_element``), end conditions (its own elimination of the tied face: u_s =
  u_m + theta x (x_s - x_m)) and condensation onto the free reference point.

Only the sparse direct solve is shared with the tets (``flexcal.fem.solve.solve_spd``: PARDISO, else
SuperLU): it is exact to round-off and discretises nothing.

Hinge frame as in ``flexcal.geometry.params``; SI. DOF order ux, uy, uz, rx, ry, rz;
compliance rows displacements, columns loads Fx, Fy, Fz, Mx, My, Mz at the free face centre.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from flexcal.geometry.params import STEEL, Material

from .reference_hex_element import HexGrid, full_stiffness, grid_nodes, tied_stiffness

__all__ = ["reference_grid", "hinge_grid", "hex27_hinge_compliance"]

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


def hinge_grid(hinge, lines) -> HexGrid:
    """The ``HexGrid`` of the notch on ``reference_grid``'s lines: every cell active,
    y = eta h(x) (the core is all of eta in [-1/2, 1/2])."""
    x_lines, eta_lines, z_lines = lines
    active = np.ones((x_lines.size - 1, eta_lines.size - 1, z_lines.size - 1), bool)
    return HexGrid(x=x_lines, p=eta_lines, z=z_lines, active=active, core_half=0.5,
                   scale=lambda x: _notch_profile(hinge, x)[0])


def _stiffness(hinge, lines, material: Material) -> tuple[sp.csr_matrix, np.ndarray]:
    """Global stiffness (3 n, 3 n) CSR and node coordinates (n, 3) [m] of the grid."""
    return full_stiffness(hinge_grid(hinge, lines), material)


def hex27_hinge_compliance(hinge, *, n_through: int = 1, refinement: int = 1, material: Material = STEEL,
                           **grid_options) -> tuple[np.ndarray, int]:
    """(compliance (6, 6) [SI] at the free face centre with the fixed face clamped, number
    of unknowns) of a circular notch hinge on the Q2 reference grid
    (``reference_grid(hinge, n_through, refinement=refinement, **grid_options)``)."""
    lines = reference_grid(hinge, n_through, refinement=refinement, **grid_options)
    grid = hinge_grid(hinge, lines)
    nodes, _ = grid_nodes(grid)
    x = nodes[:, 0]
    fixed = np.isclose(x, lines[0][0], rtol=0.0, atol=1e-12)
    free = np.isclose(x, lines[0][-1], rtol=0.0, atol=1e-12)
    K_c, n_unknowns = tied_stiffness(grid, material, [(free, np.array([lines[0][-1], 0.0, 0.0]))], clamped=fixed)
    return np.linalg.inv(K_c), n_unknowns
