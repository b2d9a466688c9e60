"""An independent reference for the 12 x 12 stiffness of chain leaf segments: 27-node
(triquadratic Lagrange) hexahedra on a multi-block grid of the exact geometry.

The part is a ``ChainSegment`` of a square block, one corner-filleted leaf and a block (the
prototype's leaf segments of the L and D chains: blocks 50 x 50 mm, leaf l 20, a 6, w 40 mm,
t 4 or 3 mm; [0, m1] with leaf 1 thin along y, [m1, s0] with leaf 2 thin along z, which is
computed turned a quarter about x onto y and the 12 x 12 turned back). What it shares with the mapped P2-tet meshes it
checks (``flexcal.fem.mesh_mapped_chain``, condensed by ``flexcal.fem.condense``) is only the
problem: the pieces (``flexcal.geometry.exact.pieces``: where the blocks and the leaf are,
the leaf's t, a, w), the material, and the end conditions (both end faces rigidly tied to
the reference points A, B on the axis at the part's ends; ux, uy, uz, rx, ry, rz at A
then B). Its discretisation is its own:

* element, assembly, ties and condensation: ``flexcal.fem.reference_hex_element`` (the
  notch reference's, generalised to a grid of blocks);
* grid: a tensor grid of parent lines, cells kept where there is material. y in three
  bands [-H/2, -c], [-c, c], [c, H/2] (c = t / 2 + a, the leaf's half height at its ends),
  z in three bands [-W/2, -w/2], [-w/2, w/2], [w/2, W/2]; in the leaf's x range only the
  centre band of each. Every block and band has cosine spacing (fine at its ends: the
  block faces the leaf meets, the re-entrant edges where the leaf's side faces meet them,
  the rims of the tied end faces), except the y core, which is uniform (the leaf's bending
  field is smooth through its thickness; cosine there made the middle cells at the
  fillets' roots, thin along x, 1.5x taller than uniform ones, and the stiffness alternated
  between odd and even counts: measured on L1, 1.3620e8 / 1.3184e8 / 1.3203e8 N/m for
  K[uy,uy] at 3 / 4 / 5 cells through); the fillets are cut uniformly in their
  arc angle (cells shrinking like angle^2 where the arc turns vertical into the block
  face), the flat part uniformly. Conforming at the block faces: the leaf's nodes there are
  the blocks' (no tie, no duplicate);
* geometry: in the centre y band y = p h_I(x) / (2 c), h_I the quadratic interpolant (at
  each cell's three x nodes) of the exact leaf height h(x) = t + 2 (a - sqrt(a^2 - d^2)),
  d the distance into the fillet (written here; h = 2 c in the blocks, so the bands meet);
  elsewhere the identity;
* refinement r multiplies every band's cell count by r (cells 1 / r in each band's
  parameter: the arc angle, the cosine angle, the flat part's length).

Chain frame as in ``flexcal.geometry.params``; SI.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from flexcal.geometry.exact import BoxPiece, pieces
from flexcal.geometry.params import STEEL, Material

from .reference_hex_element import HexGrid, grid_nodes, tied_stiffness

__all__ = ["SEGMENT_BASE_CELLS", "leaf_height", "segment_grid", "segment_unknowns", "hex27_segment_stiffness"]

# Cells of each band at refinement 1 (r multiplies them): through the leaf's core, per
# fillet arc, along the flat part, along each block (per core height 2 c of block length),
# across the y bands outside the core, across the leaf's width, across the z bands beside it.
SEGMENT_BASE_CELLS = {"through": 2, "arc": 2, "flat": 1, "block": 1, "side": 1, "width": 4, "rim": 1}


# (x, y, z) -> (x, z, -y): a quarter turn about x that takes a leaf thin along z to one thin
# along y (the blocks are square, so the part maps onto itself otherwise)
_QUARTER_TURN = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _leaf_of(params):
    """(pieces, the leaf thin along y, half section [m], turned): a leaf thin along z is
    taken turned by ``_QUARTER_TURN`` (``turned`` True)."""
    parts = pieces(params)
    leaves = [p for p in parts if not isinstance(p, BoxPiece)]
    if len(leaves) != 1:
        raise ValueError("the Q2-hex chain reference takes a segment with one leaf (the prototype's leaf segments)")
    boxes = [p for p in parts if isinstance(p, BoxPiece)]
    if len({(b.half_y, b.half_z) for b in boxes}) != 1 or boxes[0].half_y != boxes[0].half_z:
        raise ValueError("the Q2-hex chain reference takes blocks of one square section")
    leaf, turned = leaves[0], leaves[0].thin_axis == 2
    if turned:
        leaf = dataclasses.replace(leaf, thin_axis=1)
        parts = [leaf if not isinstance(p, BoxPiece) else p for p in parts]
    return parts, leaf, boxes[0].half_y, turned


def leaf_height(leaf, x: np.ndarray) -> np.ndarray:
    """Height h(x) [m] of a corner-filleted leaf along its thin axis at x [m] (its own
    formula: t in the flat part, t + 2 (a - sqrt(a^2 - d^2)) at depth d into a fillet arc,
    t + 2 a at and beyond the leaf's ends)."""
    x = np.asarray(x, float)
    a, t = leaf.fillet, leaf.thickness
    d = np.clip(np.maximum(leaf.x0 + a - x, x - (leaf.x1 - a)), 0.0, a)
    return t + 2.0 * (a - np.sqrt(a * a - d * d))


def _cosine(a: float, b: float, n: int) -> np.ndarray:
    """n cells from a to b, fine at both ends (cosine spacing); ends exact."""
    lines = a + 0.5 * (b - a) * (1.0 - np.cos(np.linspace(0.0, np.pi, n + 1)))
    lines[0], lines[-1] = a, b
    return lines


def _leaf_x_lines(leaf, n_arc: int, n_flat: int) -> np.ndarray:
    """x lines [m] over the leaf: each fillet uniform in its arc angle (phi 0 at the block
    face, where the arc is vertical), the flat part uniform."""
    a = leaf.fillet
    phi = np.linspace(0.0, 0.5 * np.pi, n_arc + 1)
    arc = a * (1.0 - np.cos(phi))  # distance from the block face
    flat = np.linspace(leaf.x0 + a, leaf.x1 - a, n_flat + 1)
    lines = np.concatenate([leaf.x0 + arc[:-1], flat, (leaf.x1 - arc)[::-1][1:]])
    lines[0], lines[-1] = leaf.x0, leaf.x1
    return lines


def _bands(inner: float, outer: float, n_inner: int, n_outer: int, *, uniform_inner: bool) -> np.ndarray:
    """Symmetric lines across [-outer, outer]: n_outer cosine cells on each side band, n_inner
    cells across [-inner, inner] (uniform or cosine)."""
    side = _cosine(inner, outer, n_outer)
    middle = np.linspace(-inner, inner, n_inner + 1) if uniform_inner else _cosine(-inner, inner, n_inner)
    return np.concatenate([-side[::-1], middle[1:-1], side])


def segment_grid(params, *, refinement: int = 1, cells: dict | None = None) -> HexGrid:
    """The reference grid (``HexGrid``) of a leaf segment (module docstring; a leaf thin along z
    turned onto y by ``_QUARTER_TURN``); ``cells``:
    overrides of ``SEGMENT_BASE_CELLS``; ``refinement`` r multiplies every count."""
    r = int(refinement)
    counts = {**SEGMENT_BASE_CELLS, **(cells or {})}
    if r < 1 or min(counts.values()) < 1:
        raise ValueError(f"refinement={refinement!r} and every cell count {counts} must be >= 1")
    parts, leaf, half_section, _ = _leaf_of(params)
    core = 0.5 * leaf.thickness + leaf.fillet
    x_parts = []
    for piece in parts:
        if piece is leaf:
            lines = _leaf_x_lines(leaf, r * counts["arc"], r * counts["flat"])
        else:
            n_block = math.ceil((piece.x1 - piece.x0) / (2.0 * core) * counts["block"] - 1e-9)
            lines = _cosine(piece.x0, piece.x1, r * n_block)
        x_parts.append(lines if not x_parts else lines[1:])
    x = np.concatenate(x_parts)
    p = _bands(core, half_section, r * counts["through"], r * counts["side"], uniform_inner=True)
    z = _bands(leaf.half_width, half_section, r * counts["width"], r * counts["rim"], uniform_inner=False)
    xm, pm, zm = 0.5 * (x[1:] + x[:-1]), 0.5 * (p[1:] + p[:-1]), 0.5 * (z[1:] + z[:-1])
    in_leaf = (xm > leaf.x0) & (xm < leaf.x1)
    footprint = (np.abs(pm) < core)[:, None] & (np.abs(zm) < leaf.half_width)[None, :]
    active = np.ones((xm.size, pm.size, zm.size), bool)
    active[in_leaf] = footprint[None]
    return HexGrid(x=x, p=p, z=z, active=active, core_half=core,
                   scale=lambda s: leaf_height(leaf, s) / (2.0 * core))


def hex27_segment_stiffness(params, *, refinement: int = 1, material: Material = STEEL, cells: dict | None = None
                            ) -> tuple[np.ndarray, int]:
    """(stiffness (12, 12) [SI] between the reference points A (x_start, 0, 0) and B
    (x_end, 0, 0), both end faces rigidly tied to them (ux, uy, uz, rx, ry, rz at A then B),
    number of unknowns) of a leaf segment on the Q2-hex reference grid
    (``segment_grid(params, refinement=..., cells=...)``)."""
    grid = segment_grid(params, refinement=refinement, cells=cells)
    nodes, _ = grid_nodes(grid)
    x = nodes[:, 0]
    ends = []
    for x_end in (grid.x[0], grid.x[-1]):
        ends.append((np.isclose(x, x_end, rtol=0.0, atol=1e-12), np.array([x_end, 0.0, 0.0])))
    k, n_unknowns = tied_stiffness(grid, material, ends)
    if _leaf_of(params)[3]:  # computed turned (v' = T v): K = T^T K' T
        T = np.kron(np.eye(4), _QUARTER_TURN)
        k = T.T @ k @ T
    return k, n_unknowns


def segment_unknowns(params, refinement: int, cells: dict | None = None) -> int:
    """Unknowns of a level before the ties (3 x the nodes of the active cells) [-]: its size
    without assembling it."""
    grid = segment_grid(params, refinement=refinement, cells=cells)
    return 3 * grid_nodes(grid)[0].shape[0]

