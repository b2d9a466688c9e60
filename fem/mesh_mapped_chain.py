"""Deterministic mapped multi-block quadratic-tet meshes of flexure chains and chain segments.

A chain (``FlexureChain``) or a slice of one (``ChainSegment``) is a row of pieces along
x (``flexcal.geometry.exact.pieces``): square blocks (end blocks, connectors, strut) and
corner-filleted leaves, leaf 1 thin in y, leaf 2 thin in z and narrower than the blocks.
Each piece is a block of one tensor grid of hexahedra over the part's bounding box; the
grid lines are shared by all pieces, so neighbouring blocks meet on the same nodes
(conforming: no coupling, no duplicate nodes at the joints):

- every size is relative to the neck cell t / n of the thinnest leaf (n = elements
  through the neck), so n refines the whole part;
- a-priori n (``cells_through``): the neck cell is also at most l / (``slenderness`` n),
  l the leaf's length, so a stubby leaf (small l / t) gets more cells through than the n
  asked for (the prototype's L leaves, l / t = 5: 8 for n = 7; the D leaves, l / t = 6.7:
  7). The error of the stiffness at a given n grows as the leaf gets stubbier: it comes
  from the roots (fillets, blocks, the re-entrant side edges), whose share of the leaf's
  compliance is about t / l (docs/meshing.md, "Convergence");
- x lines: in a leaf those of the single-hinge mapper (``mesh_mapped.mapped_grid``: at
  most ``aspect`` neck cells long on the flat part, at least ``n_arc`` cells per fillet
  arc), in a block graded from ``edge_aspect`` neck cells at a leaf face and at the part's
  end faces by ``grading`` per unit distance up to ``max_aspect`` neck cells;
- y and z lines (the cross-section): across the fillet-to-fillet height t + 2a of the
  leaves thin along that axis n uniform cells, then graded to ``side_aspect`` neck cells
  at the side faces of the leaves wide along that axis (at most ``width_aspect`` across
  the width; where a side face meets a block face, a re-entrant edge, the stress is
  singular) and to ``edge_aspect`` at the section's rims;
- each piece keeps the cells inside it: a block all, a leaf those inside its footprint
  (t + 2a by w at its ends).

The grid is then mapped: inside a leaf thin along y the lines of the core, y = eta (t + 2a),
move to y = eta t(x) (t(x) the exact leaf profile, ``LeafPiece.local_thickness``); likewise
z for leaves thin along z; elsewhere the map is the identity. Every hexahedron splits into
six Kuhn tets (``structured.grid_tet_mesh``) and every mid-edge node is the map's image of
its edge's midpoint in the parent grid: curved (isoparametric) P2 elements on the fillet
cylinders, inside the part as well as on its surface; the few tets whose curved map would
fold (where a fillet turns vertical into a block face) keep straight edges. The linear
grid is measured like any other mesh (``flexcal.fem.mesh_snap.snap_to_part``, the
``MeshReport``). Pure numpy: the same arrays on every run and machine, with or without the
compiled fTetWild seed (``fem/_entropy.c``).

Chain frame as in ``flexcal.geometry.params``; SI.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from flexcal.geometry.exact import BoxPiece, pieces
from flexcal.geometry.params import ChainSegment, FlexureChain, LeafHinge
from flexcal.geometry.profiles.leaf import LeafPiece

from .mesh import MeshReport, TetMesh
from .mesh_snap import _jacobian_ratios, snap_to_part
from .structured import _EDGES, _folded_tets, _straighten, grid_tet_mesh

__all__ = ["ChainGrid", "cells_through", "chain_grid", "template_grid", "chain_mapped_supported", "mapped_mesh_chain",
           "mapped_mesh_chain_mirror_part",
           "DEFAULT_CHAIN_OPTIONS", "FAST_CHAIN_OPTIONS",
           "PROTOTYPE_CHAIN_OPTIONS", "COARSE_PROTOTYPE_CHAIN_OPTIONS", "EXTRA_CHAIN_OPTIONS"]

# The defaults of the chain mapper, chosen by accuracy with n = 7 through the neck
# (docs/meshing.md, "Convergence": against the Richardson limit of a nested reference
# sequence, every dominant entry of the prototype's L1 and D1 leaf segments' 12 x 12 within
# 0.49 %; with n = 6 for every leaf and side cells of 3 neck cells, session 13's, 0.85 % and
# 0.61 %). slenderness: the a-priori n (``cells_through``: 8 through on the L leaves, l / t
# = 5; 7 on the D leaves, l / t = 6.7); side_aspect: the cells at the leaves' side faces,
# which bought the most accuracy per DOF of the in-plane sizes tried on L1.
DEFAULT_CHAIN_OPTIONS = {"aspect": 3.0, "n_arc": 8, "width_aspect": 12.0, "side_aspect": 1.5, "edge_aspect": 3.0,
                         "grading": 0.5, "max_aspect": 24.0, "slenderness": 5.5}
# Session 13's grid (n as given, side cells of 3 neck cells), used at n = 6: L1's leaf segments
# within 0.85 % of the nested limit, D1's 0.61 % (docs/meshing.md, "Convergence"). The
# structure assessment (validation/structure/fem_segments.py) still uses it; the virtual
# prototype's segments did until session 15.
FAST_CHAIN_OPTIONS = {**DEFAULT_CHAIN_OPTIONS, "side_aspect": 3.0, "slenderness": None}
# The grid of the virtual prototype's segments from session 16 to 24, when its cuts were tied
# rigidly (kept as the base of today's and for the measurements that compare with it), used at
# n = 7 asked for (8 through the L leaves, 7 through the D leaves): the accurate default's cells through, but its DOF
# moved to where they buy accuracy (docs/meshing.md, "The prototype's grid"): side cells of
# 1 neck cell graded fast (2 per unit distance) into the width, blocks graded twice as fast
# (block_grading 1), no refinement at the part's end faces and section rims (rim_aspect
# 24 = max_aspect), flat-part cells 2 neck cells long. Every dominant entry of the L1 and D1
# leaf segments within 0.48 % of the nested limit at 75k-86k DOF. Since session 20, 8 cells per
# fillet arc (the default's; session 16 took 6): against the Q2-hex reference limit the
# torsion K[rx,rx] of L1 [m1, s0] went from +0.506 % to +0.476 %, every dominant entry of the
# four leaf segments within 0.488 % (was 0.506 %), for +16 % of the table1 segments' CPU
# (+5 % of a cold truth's, load ~15); docs/meshing.md, "Session 20: whole chains".
COARSE_PROTOTYPE_CHAIN_OPTIONS = {**DEFAULT_CHAIN_OPTIONS, "aspect": 2.0, "side_aspect": 1.0, "grading": 2.0,
                                  "rim_aspect": 24.0, "block_grading": 1.0}
# The prototype's grid since session 25, adopted with the cuts tied through section fields
# (validation/prototype/tied_chains.py), so that the truth changed once. The ties add
# ~0.06-0.12 % to a chain's torsion, so the segments' own error must leave room: every dominant
# entry of the four leaf segments within 0.282 % of the Q2-hex reference limit (COARSE_PROTOTYPE_
# CHAIN_OPTIONS: 0.488 %, the torsion K[rx,rx]). Measured one knob at a time, the torsion error sits
# mostly in the cells through the leaf, then in the width lines and the block cells at the leaf
# faces: 10 cells through the L leaves and 8 through the D leaves at 7 asked for (slenderness
# 6.25, even_through: both mirror planes on every leaf segment, the D segments a quarter
# instead of a half), the width graded by 1 from the side faces (was 2), block cells of 2 neck
# cells at the leaf faces (was 3) graded by 0.75 along x (was 1); flat-part cells 2.5 neck cells
# long (was 2) and the largest 32 (was 24), which cost nothing measurable in accuracy; the strut
# segments' cells split in 8 (strut_refinement 2: their share of a chain's error from 0.084 %
# to 0.021 %). 1.5x the CPU of a cold table1 truth's segments. docs/meshing.md, "Session 24:
# the prototype's grid for tied cuts" (figures, cost).
PROTOTYPE_CHAIN_OPTIONS = {**COARSE_PROTOTYPE_CHAIN_OPTIONS, "slenderness": 6.25, "even_through": True,
                           "grading": 1.0, "edge_aspect": 2.0, "block_grading": 0.75, "aspect": 2.5,
                           "max_aspect": 32.0, "strut_refinement": 2}
# Options of ``chain_grid`` that the defaults leave out (None there: as the defaults'
# edge_aspect and grading), so the default grid and its cache keys stay as they were.
EXTRA_CHAIN_OPTIONS = ("rim_aspect", "block_grading", "section_grading", "cuts", "even_through",
                       "strut_refinement")


@dataclass(frozen=True, kw_only=True, eq=False)
class ChainGrid:
    """The parent grid of a chain mesh and its map.

    x, p, q: grid lines along x, y, z in the parent space [m] (p, q: the cross-section
    coordinates the leaves' ends have, y = p outside a core); active (n_x, n_y, n_z) bool:
    the cells inside the part; cores: axis (1 = y, 2 = z) -> (half core height (t + 2a) / 2 [m],
    the leaves thin along that axis).
    """

    x: np.ndarray
    p: np.ndarray
    q: np.ndarray
    active: np.ndarray
    cores: dict

    def physical(self, parent: np.ndarray) -> np.ndarray:
        """Points (n, 3) of the part [m] from parent points (n, 3) [m]: in a leaf's core
        the thin coordinate scales with t(x) / (t + 2a) (module docstring)."""
        out = np.array(parent, float, copy=True)
        for axis, (half, leaves) in self.cores.items():
            inside = np.abs(parent[:, axis]) <= half * (1 + 1e-12)
            for leaf in leaves:
                here = inside & (parent[:, 0] >= leaf.x0) & (parent[:, 0] <= leaf.x1)
                scale = leaf.local_thickness(parent[here, 0]) / (2.0 * half)
                out[here, axis] = parent[here, axis] * scale
        return out


def _leaves(params) -> list[LeafPiece]:
    return [p for p in pieces(params) if not isinstance(p, BoxPiece)]


def chain_mapped_supported(params) -> bool:
    """True for a ``FlexureChain`` or ``ChainSegment`` whose compliant pieces are leaves
    no higher and no wider than its section (every valid chain)."""
    if not isinstance(params, (FlexureChain, ChainSegment)):
        return False
    return all(isinstance(p, LeafPiece) for p in _leaves(params))


def _graded(a: float, b: float, h_a: float | None, h_b: float | None, grading: float, h_max: float) -> np.ndarray:
    """Lines from a to b [m] (both included): cell size min(h_max, h_a + g (s - a),
    h_b + g (b - s)) (h_a / h_b None: no bound from that end)."""
    s = np.linspace(a, b, 2001)
    size = np.full_like(s, h_max)
    if h_a is not None:
        size = np.minimum(size, h_a + grading * (s - a))
    if h_b is not None:
        size = np.minimum(size, h_b + grading * (b - s))
    density = 1.0 / size
    cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(s))])
    n = max(1, math.ceil(cumulative[-1] - 1e-9))
    lines = np.interp(np.linspace(0.0, cumulative[-1], n + 1), cumulative, s)
    lines[0], lines[-1] = a, b
    return lines


def _section_lines(axis: int, leaves: list[LeafPiece], half_section: float, n: int, width_cell: float,
                   side_cell: float, edge_cell: float, grading: float, h_max: float,
                   outer_grading: float | None = None) -> tuple[np.ndarray, float | None]:
    """Cross-section lines along ``axis`` (1 = y, 2 = z) [m], symmetric, and the half core
    height [m] (None when no leaf is thin along this axis): n uniform cells across the core
    t + 2a of the leaves thin along this axis, then graded towards the side faces of the
    leaves wide along it (cells of ``side_cell`` there: where a side face meets a block
    face the stress is singular) and out to the section (``edge_cell`` at its rims)."""
    thin = [leaf for leaf in leaves if leaf.thin_axis == axis]
    wide = [leaf for leaf in leaves if leaf.width_axis == axis]
    core = None
    if thin:
        heights = {round(leaf.thickness + 2 * leaf.fillet, 12) for leaf in thin}
        if len(heights) > 1:
            raise ValueError("the chain mapper needs every leaf thin along one axis to reach the same height t + 2a")
        core = 0.5 * heights.pop()
    outer = grading if outer_grading is None else outer_grading
    if not thin and not wide:
        half = _graded(0.0, half_section, None, edge_cell, outer, h_max)[1:]
        return np.concatenate([-half[::-1], [0.0], half]), None
    if core is not None:
        # (2 k - n) / n exactly: symmetric, and 0 exactly in the middle for even n, where
        # linspace(-core, core, n + 1) can put it at +-1e-19 and the mirror below then
        # doubled it into a flat layer of cells (a singular K on table1 seed 2)
        positive = [core * (2.0 * np.arange(n + 1) - n) / n]
        reach, size = core, 2.0 * core / n
    else:
        positive, reach, size = [], 0.0, None
    if wide:
        half_width = max(leaf.half_width for leaf in wide)
        if half_width > reach * (1 + 1e-9):
            lines = _graded(reach, half_width, size, side_cell, grading, width_cell)
            positive.append(lines[1:])
            reach = half_width
        size = side_cell
    if half_section > reach * (1 + 1e-9):  # graded towards the section's edges too (the end faces' rims)
        positive.append(_graded(reach, half_section, size, edge_cell, outer, h_max)[1:])
    half = np.concatenate(positive)
    half = half[half > 0]
    middle = [0.0] if (core is None or n % 2 == 0) else []
    return np.concatenate([-half[::-1], middle, half]), core


def _leaf_lines(leaf: LeafPiece, n: int, aspect: float, n_arc: float) -> np.ndarray:
    """x lines [m] over a leaf, as the single-hinge mapper draws them (``mapped_grid``)."""
    from .mesh_mapped import mapped_grid

    hinge = LeafHinge(length=leaf.x1 - leaf.x0, thickness=leaf.thickness, width=2 * leaf.half_width,
                      fillet=leaf.fillet, block_length=leaf.x1 - leaf.x0)
    x, _, _ = mapped_grid(hinge, n, aspect=aspect, n_arc=n_arc)
    half = 0.5 * (leaf.x1 - leaf.x0)
    x = x[np.abs(x) <= half * (1 + 1e-12)]
    x[0], x[-1] = -half, half
    return 0.5 * (leaf.x0 + leaf.x1) + x


def _refine(lines: np.ndarray, r: int) -> np.ndarray:
    """Every interval split into r equal ones (nested grids)."""
    if r == 1:
        return lines
    t = np.linspace(0.0, 1.0, r + 1)[:-1]
    inner = (lines[:-1, None] + np.diff(lines)[:, None] * t[None, :]).ravel()
    return np.concatenate([inner, lines[-1:]])


def cells_through(params, n_thickness: int, slenderness: float | None, even: bool = False) -> int:
    """Cells across the thinnest leaf's neck for ``n_thickness`` requested [-]: n, or more
    where a leaf is stubbier than ``slenderness`` (length l / thickness t): the neck cell
    t / n is at most l / (slenderness n) for every leaf (module docstring, "a-priori n").
    None: n as given. even: an odd count raised by one, so that the core of the leaves
    has a grid line at its middle and the part both mirror planes
    (``mapped_mesh_chain_mirror_part``: a quarter, condensed in four parity classes, instead
    of a half in two). A part without leaves: n (its section always has both planes)."""
    n = int(n_thickness)
    leaves = _leaves(params)
    if not leaves:
        return n
    if slenderness is not None:
        if not (math.isfinite(slenderness) and slenderness > 0):
            raise ValueError(f"slenderness={slenderness!r} must be > 0 (or None to take n as given)")
        cell = min(min(leaf.thickness for leaf in leaves) / n,
                   min(leaf.x1 - leaf.x0 for leaf in leaves) / (slenderness * n))
        # 1e-9: t / cell is n exactly (to round-off) when no leaf is stubbier than the bound
        n = max(n, math.ceil(min(leaf.thickness for leaf in leaves) / cell - 1e-9))
    return n + n % 2 if even else n


def chain_grid(params, n_thickness: int, *, aspect: float = 3.0, n_arc: int = 8, width_aspect: float = 12.0,
               side_aspect: float = 1.5, edge_aspect: float = 3.0, grading: float = 0.5, max_aspect: float = 24.0,
               slenderness: float | None = 5.5, refinement: int = 1, rim_aspect: float | None = None,
               block_grading: float | None = None, section_grading: float | None = None,
               cuts: tuple[float, ...] | None = None, even_through: bool = False,
               strut_refinement: int = 1) -> ChainGrid:
    """The parent grid of a chain or segment (module docstring).

    n_thickness: cells across every leaf's core (so across t at its neck), raised by
    ``cells_through`` for leaves stubbier than ``slenderness`` (l / t; None: n as given);
    aspect: leaf cell length / neck cell height on the flat part; n_arc: least cells per
    fillet arc; width_aspect: leaf cell width / neck cell height across the width (the
    thinnest leaf); side_aspect: cell width at the leaves' side faces / neck cell height
    (the re-entrant edges where they meet the blocks); edge_aspect: the same at the blocks'
    faces next to a leaf, the part's end faces and the section's rims;
    grading: growth of the cell size per unit distance away from the leaves, the end faces
    and the section's edges [-]; max_aspect: largest cell / neck cell (at most half the
    section); refinement: every cell split
    into refinement^3 (nested meshes for convergence studies); rim_aspect: the cells at the
    part's end faces and the section's rims / neck cell (None: edge_aspect; max_aspect: no
    refinement there); block_grading: the grading along x in the blocks (None: grading);
    section_grading: the grading of the section lines outside the leaves' footprint (None:
    block_grading). The last three are the prototype's (``PROTOTYPE_CHAIN_OPTIONS``).
    cuts: x [m] of cross-sections inside blocks that get a grid line each, graded as the
    part's end faces (``rim_aspect``): the part cut there into the segments the prototype
    condenses has, along x, exactly those segments' lines (docs/meshing.md, "Session 20:
    whole chains"; None: no cuts). even_through: an odd number of cells through the leaves
    raised by one (``cells_through``; both mirror planes on every leaf segment);
    strut_refinement: a part without leaves (a segment of strut) has every cell split into
    strut_refinement^3 on top of ``refinement`` (its cells are sized from a quarter of the
    section, so at 1 the strut segments are coarse: docs/meshing.md, "Session 24").
    """
    if not chain_mapped_supported(params):
        raise ValueError(f"the chain mapper takes a FlexureChain or ChainSegment of leaves, got {type(params).__name__}")
    n = cells_through(params, n_thickness, slenderness, even_through)
    ps = pieces(params)
    leaves = _leaves(params)
    half_section = max(max(p.half_y, p.half_z) for p in ps if isinstance(p, BoxPiece))
    # every size relative to the neck cell t / n of the thinnest leaf, so that n refines all
    # of the part (a segment of strut alone: as if its leaves were a quarter section thick)
    cell = min((leaf.thickness for leaf in leaves), default=0.5 * half_section) / n
    h_max = min(max_aspect * cell, half_section)
    width_cell = min(width_aspect * cell, h_max)
    edge_cell = min(edge_aspect * cell, h_max)
    rim_cell = edge_cell if rim_aspect is None else min(rim_aspect * cell, h_max)
    block_grading = grading if block_grading is None else block_grading
    outer_grading = block_grading if section_grading is None else section_grading
    side_cell = min(side_aspect * cell, h_max)
    p, core_y = _section_lines(1, leaves, half_section, n, width_cell, side_cell, rim_cell, grading, h_max,
                               outer_grading)
    q, core_z = _section_lines(2, leaves, half_section, n, width_cell, side_cell, rim_cell, grading, h_max,
                               outer_grading)
    # x: leaves as the hinge mapper, blocks graded away from the leaf faces
    x_parts: list[np.ndarray] = []
    for i, piece in enumerate(ps):
        if isinstance(piece, LeafPiece):
            lines = _leaf_lines(piece, n, aspect, n_arc)
        else:
            def face_cell(j: int) -> float | None:  # fine at a leaf's face and at the part's end
                # faces (where the stress is singular: re-entrant edges, rims of the coupled faces)
                if j < 0 or j >= len(ps):
                    return rim_cell
                return edge_cell if isinstance(ps[j], LeafPiece) else None

            inside = [c for c in (cuts or ()) if piece.x0 + 1e-9 < c < piece.x1 - 1e-9]
            ends = [piece.x0, *sorted(inside), piece.x1]
            bounds = [face_cell(i - 1), *[rim_cell] * (2 * len(inside)), face_cell(i + 1)]
            lines = np.concatenate([_graded(a, b, bounds[2 * k], bounds[2 * k + 1], block_grading, h_max)[k > 0:]
                                    for k, (a, b) in enumerate(zip(ends[:-1], ends[1:]))])
        x_parts.append(lines if not x_parts else lines[1:])
    x = np.concatenate(x_parts)
    if int(strut_refinement) != strut_refinement or strut_refinement < 1:
        raise ValueError(f"strut_refinement={strut_refinement!r} must be a positive integer")
    r = int(refinement) * (1 if leaves else int(strut_refinement))
    x, p, q = _refine(x, r), _refine(p, r), _refine(q, r)
    for name, lines in (("x", x), ("y", p), ("z", q)):
        if np.min(np.diff(lines)) < 1e-6 * cell:  # a flat layer of cells: its tets have no volume
            raise RuntimeError(f"the chain mapper made a flat layer of cells along {name} (lines "
                               f"{np.min(np.diff(lines)):.3g} m apart); please report this chain's dimensions")
    return ChainGrid(x=x, p=p, q=q, active=_active_cells(x, p, q, ps), cores=_cores(leaves, core_y, core_z))


def _active_cells(x: np.ndarray, p: np.ndarray, q: np.ndarray, ps) -> np.ndarray:
    """(n_x, n_y, n_z) bool: the cells of the grid lines x, p, q [m] inside one of the pieces ``ps``."""
    xm, pm, qm = 0.5 * (x[1:] + x[:-1]), 0.5 * (p[1:] + p[:-1]), 0.5 * (q[1:] + q[:-1])
    active = np.zeros((len(xm), len(pm), len(qm)), bool)
    for piece in ps:
        rows = (xm > piece.x0) & (xm < piece.x1)
        half_y, half_z = piece.end_extent()
        inside = (np.abs(pm)[:, None] < half_y) & (np.abs(qm)[None, :] < half_z)
        active[rows] = inside[None]
    return active


def _cores(leaves, core_y: float | None, core_z: float | None) -> dict:
    """``ChainGrid.cores`` of ``leaves`` with the half core heights along y and z [m] (None: none)."""
    cores = {}
    if core_y is not None:
        cores[1] = (core_y, tuple(leaf for leaf in leaves if leaf.thin_axis == 1))
    if core_z is not None:
        cores[2] = (core_z, tuple(leaf for leaf in leaves if leaf.thin_axis == 2))
    return cores


def _x_features(params) -> np.ndarray:
    """The x [m] of ``params``' features along its axis, ascending: every piece's ends and each
    leaf's fillet ends (x0 + a, x1 - a)."""
    out = []
    for piece in pieces(params):
        out += [piece.x0, piece.x1]
        if isinstance(piece, LeafPiece) and piece.fillet > 0:
            out += [piece.x0 + piece.fillet, piece.x1 - piece.fillet]
    return np.unique(np.asarray(out, float))


def _section_features(params, axis: int, *, exact: bool = False) -> np.ndarray:
    """The distances from the axis [m] of ``params``' features across its section along ``axis``
    (1 = y, 2 = z), ascending from 0: the cores (t + 2a) / 2 of the leaves thin along it (rounded
    to 1e-12 m as ``_section_lines`` rounds them, unless ``exact``), the half widths of those wide
    along it, the blocks' half extents."""
    out = [0.0]
    for piece in pieces(params):
        if isinstance(piece, BoxPiece):
            out.append(piece.half_y if axis == 1 else piece.half_z)
        elif piece.thin_axis == axis:  # as _section_lines rounds the core
            height = piece.thickness + 2 * piece.fillet
            out.append(0.5 * (height if exact else round(height, 12)))
        elif piece.width_axis == axis:
            out.append(piece.half_width)
    return np.unique(np.asarray(out, float))


def template_grid(params, template, n_thickness: int, **options) -> ChainGrid:
    """The parent grid of ``params`` with the cells of ``template``'s (``chain_grid`` of the
    template with ``n_thickness`` and ``options``): the same counts along every line and the same
    active cells, so their meshes have one connectivity, node for node, whatever the dimensions
    (a chain and its design's nominal one: the model's moved chains, an as-built chain).

    Each family of lines is mapped piecewise linearly from the template's features to those of
    ``params`` (``_x_features``: piece ends and fillet ends; ``_section_features``: cores, leaf
    half widths, section), so every feature of ``params`` is a grid line where it is one of the
    template's and the cores follow ``params``' leaves. ValueError if the two do not have the
    same features in the same order (another kind of part, a leaf more) or the mapped lines
    keep other cells."""
    if not (chain_mapped_supported(params) and chain_mapped_supported(template)):
        raise ValueError("template_grid takes two FlexureChains or ChainSegments of leaves")
    grid = chain_grid(template, n_thickness, **options)
    if params == template:
        return grid
    maps = [(_x_features(template), _x_features(params))]
    # the section's features moved by their exact change from the template's (the template's own
    # rounded to 1e-12 m as its lines are): the part's lines then follow its dimensions smoothly
    # and tend to the template's as they tend to its dimensions (the rounded cores stepped by up
    # to 5e-13 m, which a shape derivative's second differences at 1e-4 divide by 1e-8)
    for axis in (1, 2):
        rounded, exact = _section_features(template, axis), _section_features(template, axis, exact=True)
        moved = _section_features(params, axis, exact=True)
        maps.append((rounded, rounded + (moved - exact) if moved.shape == exact.shape else moved))
    if any(a.shape != b.shape or np.any(np.diff(b) <= 0) for a, b in maps):
        raise ValueError("the part and its template do not have the same features (pieces, leaves, section) "
                         "in the same order: not one design")
    # a family whose features did not move keeps its lines to the bit (np.interp's round-off would
    # move them by ~1e-17 m, which a shape derivative's differences divide by its step)
    x = grid.x if np.array_equal(*maps[0]) else np.interp(grid.x, *maps[0])
    p, q = (lines if np.array_equal(*m) else np.sign(lines) * np.interp(np.abs(lines), *m)
            for lines, m in zip((grid.p, grid.q), maps[1:]))
    ps, leaves = pieces(params), _leaves(params)
    if not np.array_equal(_active_cells(x, p, q, ps), grid.active):
        raise ValueError("the part's pieces keep other cells of its template's grid: not one design")
    core = {axis: (maps[axis][1][np.argmin(np.abs(maps[axis][0] - grid.cores[axis][0]))] if axis in grid.cores
                   else None) for axis in (1, 2)}
    return ChainGrid(x=x, p=p, q=q, active=grid.active, cores=_cores(leaves, core[1], core[2]))


def _quadratic_mesh(grid: ChainGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(parent nodes (n, 3) [m], tets (m, 10), corner node ids) of the active cells, the
    corners numbered first; unused grid nodes dropped."""
    full = grid_tet_mesh(grid.x, grid.p, grid.q)
    tets = full.tets.reshape(-1, 6, 10)[grid.active.ravel()].reshape(-1, 10)
    corners = np.unique(tets[:, :4])
    mids = np.setdiff1d(np.unique(tets[:, 4:]), corners, assume_unique=True)
    order = np.concatenate([corners, mids])
    new = np.full(len(full.nodes), -1, np.int64)
    new[order] = np.arange(len(order))
    return full.nodes[order], new[tets], np.arange(len(corners))


def mapped_mesh_chain(params, *, elements_through_thickness: float = 7, refinement: int = 1,
                      measure: bool = True, quality: bool = True, **options) -> tuple[TetMesh, MeshReport]:
    """Mapped quadratic tet mesh of a chain or chain segment (parameters, not a CAD solid)
    and its report (as ``mesh_part``). elements_through_thickness: n asked for, raised for
    stubby leaves (``cells_through``; the report's ``cells_through`` says what was used).
    Options as ``chain_grid`` (defaults ``DEFAULT_CHAIN_OPTIONS``). ``measure=False`` skips the boundary measurements of
    ``snap_to_part`` (the report then has NaN there); the mesh is the same. ``quality=False``
    with it skips the report's Jacobian ratios and volumes too (NaN; 0.6 s of CPU over the
    18 segments of a cold table1 truth, which only keeps the mesh).
    Raises ValueError for a part it cannot map or bad options.
    """
    from .mesh_mapped import MAX_MAPPED_DOF

    n_float = float(elements_through_thickness)
    if not (math.isfinite(n_float) and n_float >= 1):
        raise ValueError(f"elements_through_thickness={elements_through_thickness!r} must be >= 1")
    if int(refinement) != refinement or refinement < 1:
        raise ValueError(f"refinement={refinement!r} must be a positive integer")
    unknown = set(options) - set(DEFAULT_CHAIN_OPTIONS) - set(EXTRA_CHAIN_OPTIONS)
    if unknown:
        raise ValueError(f"unknown chain mesh options {sorted(unknown)}; use "
                         f"{sorted(set(DEFAULT_CHAIN_OPTIONS) | set(EXTRA_CHAIN_OPTIONS))}")
    settings = {**DEFAULT_CHAIN_OPTIONS, **options}
    n = math.ceil(n_float - 1e-9)
    timings: dict[str, float] = {}
    cpu0 = time.process_time()
    t0 = time.perf_counter()
    grid = chain_grid(params, n, refinement=int(refinement), **settings)
    n_dof_bound = 3 * (2 * len(grid.x) - 1) * (2 * len(grid.p) - 1) * (2 * len(grid.q) - 1) * grid.active.mean()
    if n_dof_bound > MAX_MAPPED_DOF:
        raise ValueError(f"the mesh would have about {n_dof_bound:,.0f} DOF (limit {MAX_MAPPED_DOF:,}: the solver "
                         f"would run out of memory); use fewer elements through the thickness or less refinement")
    parent, tets, corners = _quadratic_mesh(grid)
    nodes = grid.physical(parent)
    timings["grid"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    n_straight = _unfold(nodes, parent, tets)
    mesh = TetMesh(nodes, tets)
    timings["map"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    through = cells_through(params, n, settings["slenderness"], settings.get("even_through", False))
    if measure:
        measured = _measure(params, mesh, corners, through)
    else:
        measured = _unmeasured(params, mesh, len(corners), volumes=quality)
    ratio = float(_jacobian_ratios(mesh.nodes, mesh.tets).min()) if measure or quality else float("nan")
    measured.update(min_jacobian_ratio=ratio, n_straight_mid=n_straight)
    timings["measure"] = time.perf_counter() - t0
    timings["cpu"] = time.process_time() - cpu0
    report = MeshReport(
        n_nodes=mesh.n_nodes, n_tets=mesh.n_tets, epsilon=0.0, n_retries=0, retry_reasons=(),
        options=dict(mesher="mapped", elements_through_thickness=float(n), refinement=int(refinement), **settings,
                     cells_through=through,
                     n_cells=[len(grid.x) - 1, len(grid.p) - 1, len(grid.q) - 1], n_hexes=int(grid.active.sum())),
        timings=timings, **measured)
    return mesh, report


def mapped_mesh_chain_mirror_part(params, *, elements_through_thickness: float = 7, refinement: int = 1,
                                  template=None, **options) -> tuple[TetMesh, tuple[int, ...]]:
    """(mesh, mirror axes): the mapped mesh's part on y >= 0 and / or z >= 0, for a
    condensation that uses the part's two mirror planes (``flexcal.fem.condense.
    mirrored_chain_stiffness``). A chain or segment is symmetric about y = 0 and z = 0 (its
    leaves are centred in the square section); a mirror axis is one whose grid lines hold
    the exact 0 (an even number of cells across the section: on the prototype's grid both
    for the L leaf segments, 8 through, z alone for the D leaf segments, 7 through, whose
    thin axis y has its middle inside a cell), so the part's nodes on the plane have the
    coordinate 0 exactly. The part keeps the full mesh's cells in that quadrant or half
    (the same Kuhn split in every cell); its mirror images make a conforming mesh of the
    whole part, the full grid with the diagonals of the mirrored cells mirrored.
    Options, n and refinement as ``mapped_mesh_chain`` (no report, no measuring); template: a
    part of the same design whose cells the mesh takes (``template_grid``: one connectivity for
    both), None: its own."""
    n_float = float(elements_through_thickness)
    if not (math.isfinite(n_float) and n_float >= 1):
        raise ValueError(f"elements_through_thickness={elements_through_thickness!r} must be >= 1")
    unknown = set(options) - set(DEFAULT_CHAIN_OPTIONS) - set(EXTRA_CHAIN_OPTIONS)
    if unknown:
        raise ValueError(f"unknown chain mesh options {sorted(unknown)}")
    if int(refinement) != refinement or refinement < 1:
        raise ValueError(f"refinement={refinement!r} must be a positive integer")
    settings = {**DEFAULT_CHAIN_OPTIONS, **options}
    grid = (chain_grid(params, math.ceil(n_float - 1e-9), refinement=int(refinement), **settings) if template is None
            else template_grid(params, template, math.ceil(n_float - 1e-9), refinement=int(refinement), **settings))
    p, q, active = grid.p, grid.q, grid.active
    axes = []
    if np.any(p == 0.0):
        axes.append(1)
        active, p = active[:, p[:-1] >= 0.0], p[p >= 0.0]
    if np.any(q == 0.0):
        axes.append(2)
        active, q = active[:, :, q[:-1] >= 0.0], q[q >= 0.0]
    part = ChainGrid(x=grid.x, p=p, q=q, active=active, cores=grid.cores)
    parent, tets, _ = _quadratic_mesh(part)
    nodes = part.physical(parent)
    _unfold(nodes, parent, tets)
    return TetMesh(nodes, tets), tuple(axes)


def _unfold(nodes: np.ndarray, parent: np.ndarray, tets: np.ndarray) -> int:
    """Straighten (in place) the edges of tets whose curved map folds; returns how many
    mid-nodes were put back on their chords. Only tets touching a leaf can fold."""
    curved = np.flatnonzero(np.any(np.abs(nodes[tets] - parent[tets]) > 0, axis=(1, 2)))
    straight: set[int] = set()
    for _ in range(10):
        folded = curved[_folded_tets(nodes, tets[curved])]
        if folded.size == 0:
            return len(straight)
        straight.update(tets[folded, 4:].ravel().tolist())
        _straighten(nodes, tets, folded)
    raise RuntimeError("could not unfold the mapped chain mesh; use the tetwild mesher")  # pragma: no cover


def _measure(params, mesh: TetMesh, corners: np.ndarray, n: int) -> dict:
    """The ``MeshReport`` fields of ``snap_to_part`` for the linear corner mesh (its
    corners lie on the exact surfaces already), with the volume of the curved mesh."""
    thin = min((leaf.thickness for leaf in _leaves(params)), default=None)
    tolerance = 0.3 * (thin / n if thin else 1e-4)  # below a neck cell: no node put on a surface it is not on
    nodes4 = mesh.nodes[corners]
    _, measured = snap_to_part(params, nodes4, mesh.tets[:, :4], tolerance=tolerance, project=True, morph=False)
    measured.update(volume=mesh.volume, volume_error=mesh.volume / measured["volume_exact"] - 1.0)
    return measured


def _unmeasured(params, mesh: TetMesh, n_corner: int, volumes: bool = True) -> dict:
    from flexcal.geometry.exact import exact_volume

    nan = float("nan")
    exact, volume = (exact_volume(params), mesh.volume) if volumes else (nan, nan)
    return dict(n_corner_nodes=n_corner, radius_ratio_min=nan, radius_ratio_median=nan, min_dihedral_deg=nan,
                volume=volume, volume_exact=exact, volume_error=volume / exact - 1.0,
                volume_error_raw=nan, max_surface_deviation=nan, max_surface_deviation_raw=nan,
                end_plane_deviation=nan, n_unassigned=0, n_demoted=0, n_unsnapped=0, necks=())
