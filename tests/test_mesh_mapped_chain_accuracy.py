"""Accuracy of the chain mapper's default mesh (flexcal.fem.mesh_mapped_chain, issue #26):
every dominant entry of the prototype's leaf segments within 0.5 % of a converged reference
(docs/meshing.md, "Convergence")."""

import functools
import math

import numpy as np
import pytest

from flexcal.fem.mesh_mapped_chain import DEFAULT_CHAIN_OPTIONS, cells_through, chain_grid, mapped_mesh_chain
from flexcal.geometry.params import ChainSegment, reference_mechanism
from flexcal.validation.prototype.segments import section_nodes

CHAINS = {c.name: c.chain for c in reference_mechanism().chains}  # L1: t 4 mm, D1: t 3 mm; both l 20 mm


def _segment(name: str, k: int) -> ChainSegment:
    nodes = section_nodes(CHAINS[name])
    return ChainSegment(chain=CHAINS[name], x_start=float(nodes[k]), x_end=float(nodes[k + 1]))


def test_stubby_leaves_get_more_cells_through():
    # the a-priori n: neck cell t / n at most l / (slenderness n). D1's leaves (l / t = 6.7)
    # are slender enough for n; L1's (l / t = 5) get n * 5.5 / 5 rounded up
    slenderness = DEFAULT_CHAIN_OPTIONS["slenderness"]
    assert slenderness == 5.5
    assert [cells_through(_segment("D1", 0), n, slenderness) for n in (2, 4, 6, 7, 8)] == [2, 4, 6, 7, 8]
    assert [cells_through(_segment("L1", 0), n, slenderness) for n in (2, 4, 6, 7, 8)] == [3, 5, 7, 8, 9]
    assert cells_through(_segment("L1", 0), 7, None) == 7  # None: n as given (nested studies)
    strut = _segment("L1", 2)  # no leaf: n as given
    assert cells_through(strut, 7, slenderness) == 7
    with pytest.raises(ValueError, match="slenderness"):
        cells_through(_segment("L1", 0), 7, 0.0)
    # the default grid (n = 7 asked for) of L1 has 8 cells across the core t + 2a of its leaf 1
    grid = chain_grid(_segment("L1", 0), 7, **DEFAULT_CHAIN_OPTIONS)
    core = CHAINS["L1"].thickness_1 + 2 * CHAINS["L1"].fillet
    # lines strictly inside the core's half height 0.5 core (1e-9: its end line, exact to round-off)
    assert np.count_nonzero(np.abs(grid.p) < 0.5 * core * (1 - 1e-9)) + 1 == 8


def test_cells_are_fine_at_the_leaves_side_faces():
    # the re-entrant edges where a leaf's side face meets a block face: side_aspect neck
    # cells wide on both sides of the side face (z = +-w/2 for leaf 1)
    segment = _segment("D1", 0)
    grid = chain_grid(segment, 6, **DEFAULT_CHAIN_OPTIONS)
    cell = CHAINS["D1"].thickness_1 / 6
    half_width = 0.5 * CHAINS["D1"].width
    at = int(np.argmin(np.abs(grid.q - half_width)))
    assert grid.q[at] == pytest.approx(half_width, abs=1e-12)  # a grid line on the side face (round-off of mm sums)
    widths = np.diff(grid.q)[[at - 1, at]]
    # a graded cell holds at most one unit of the density 1 / (h + g s) from its fine end:
    # w <= h (e^g - 1) / g (1.30 h at g = 0.5); measured 0.745 and 0.921 mm for h = 0.75 mm
    g = DEFAULT_CHAIN_OPTIONS["grading"]
    # 1e-9: the bound is exact, the margin only covers round-off
    assert np.all(widths <= DEFAULT_CHAIN_OPTIONS["side_aspect"] * cell * math.expm1(g) / g * (1 + 1e-9))
    # and finer than the former default (3 neck cells at the side faces: 1.5 mm here)
    former = chain_grid(segment, 6, **{**DEFAULT_CHAIN_OPTIONS, "side_aspect": 3.0})
    assert np.diff(former.q)[int(np.argmin(np.abs(former.q - half_width)))] > widths.max()


def _stiffness(segment: ChainSegment, **mesh_options) -> np.ndarray:
    from flexcal.fem.condense import chain_stiffness
    from flexcal.geometry.exact import end_planes, reference_points
    from flexcal.geometry.params import STEEL

    mesh, _ = mapped_mesh_chain(segment, measure=False, **mesh_options)
    planes, points = end_planes(segment), reference_points(segment)
    k = chain_stiffness(mesh, STEEL, planes["A"], points["A"], planes["B"], points["B"])
    return 0.5 * (k + k.T)


# the reference family: the grid at 2 cells through (the former options: side cells as the
# block faces', n as given) split into r^3 for r = 2, 3, 4 (nested, h = 1 / r exactly)
REFERENCE = dict(elements_through_thickness=2, side_aspect=3.0, slenderness=None)


@functools.lru_cache(maxsize=None)
def _reference(name: str, k: int):
    """(Richardson limit (12, 12) [SI], dominant-entry mask) of the nested sequence, after
    checking that it is one: monotone from above at a rate of its own."""
    from flexcal.fem.convergence import dominant_entries, richardson
    from flexcal.validation.reports.fem import DOMINANT_FRACTION

    segment = _segment(name, k)
    levels = np.array([2.0, 3.0, 4.0])
    nested = np.array([_stiffness(segment, refinement=int(r), **REFERENCE) for r in levels])
    fit = richardson(1.0 / levels, nested)
    mask = dominant_entries(nested[-1], DOMINANT_FRACTION)
    excess = ((nested - fit.limit) / np.abs(fit.limit) * np.sign(fit.limit))[:, mask]
    monotone = (excess[0] > excess[1]) & (excess[1] > excess[2]) & (excess[2] > 0)
    # from above, monotone, at a rate of its own on all but round-off entries (L1 leaf 2's
    # K[rzA,rzB] changes by < 0.02 % between levels and not monotonically: measured)
    assert monotone.mean() > 0.9
    # rate >= 1.2: the re-entrant edges' r^-0.46 stresses give ~1.1 under uniform
    # refinement, the smooth part 4 (P2); measured 1.44-2.93
    assert np.all(fit.rate[mask][monotone] > 1.2)
    return fit.limit, mask


def _largest_error(name: str, k: int, **mesh_options) -> float:
    """Largest relative error [-] of a dominant entry of the mesh's 12 x 12 against the
    nested reference."""
    limit, mask = _reference(name, k)
    stiffness = _stiffness(_segment(name, k), **mesh_options)
    error = float((np.abs(stiffness - limit)[mask] / np.abs(limit[mask])).max())
    assert math.isfinite(error)
    return error


@pytest.mark.slow
@pytest.mark.parametrize("name, k", [("L1", 0), ("L1", 1), ("D1", 0), ("D1", 1)],
                         ids=["L1 leaf 1", "L1 leaf 2", "D1 leaf 1", "D1 leaf 2"])
def test_default_mesh_within_half_a_percent_of_the_converged_stiffness(name, k):
    """The issue's goal: every dominant entry of the chain mapper's default mesh's 12 x 12
    (``mapped_mesh_chain``'s defaults, what ``flexcal chain`` builds) within 0.5 % of the
    Richardson limit of a nested sequence of another grid family (measured: L1 0.486 % and
    0.325 %, D1 0.419 % and 0.367 %). The prototype's segments have a cheaper grid of their
    own (``PROTOTYPE_CHAIN_OPTIONS``; the test below)."""
    error = _largest_error(name, k)
    # 0.005: the 0.5 % goal on every dominant entry
    assert error < 0.005, f"largest error {100 * error:.3f} % of a dominant entry"


@pytest.mark.slow
@pytest.mark.parametrize("name, k", [("L1", 0), ("L1", 1), ("D1", 0), ("D1", 1)],
                         ids=["L1 leaf 1", "L1 leaf 2", "D1 leaf 1", "D1 leaf 2"])
def test_the_prototypes_grid_within_half_a_percent_of_the_converged_stiffness(name, k, tmp_path):
    """The same goal for the 12 x 12 the virtual prototype's provider builds
    (``segment_stiffness_fem``: ``DEFAULT_ELEMENTS_THROUGH`` asked for, ``PROTOTYPE_CHAIN_OPTIONS``;
    its own empty cache), against the nested reference computed here (measured 2026-11-27:
    L1 0.435 % and 0.437 %, D1 0.451 % and 0.479 %; session 13's fast grid 0.848 %, 0.843 %,
    0.606 %, 0.578 %; since session 17 the provider condenses the mirror part,
    ``mirrored_chain_stiffness``: L1 0.446 % and 0.448 %, D1 0.451 % and 0.479 %, 2026-11-28)."""
    from flexcal.validation.prototype.fem_provider import segment_stiffness_fem

    limit, mask = _reference(name, k)
    stiffness = segment_stiffness_fem(_segment(name, k), cache_directory=tmp_path)
    error = float((np.abs(stiffness - limit)[mask] / np.abs(limit[mask])).max())
    # 0.005: the 0.5 % goal on every dominant entry
    assert error < 0.005, f"largest error {100 * error:.3f} % of a dominant entry"


def test_the_prototypes_grid_is_coarse_away_from_the_leaves():
    # where the prototype's grid saves its DOF (docs/meshing.md, "The prototype's grid"):
    # no refinement at the part's end faces and the section's rims, so a strut segment
    # (no leaf) is a few cells before its own strut_refinement (session 24: every cell split in
    # 2^3 for the tied cuts' fields); the leaves get at least the accurate grid's cells through
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS
    from flexcal.validation.prototype.fem_provider import DEFAULT_ELEMENTS_THROUGH

    strut = _segment("L1", 2)
    fine = chain_grid(strut, DEFAULT_ELEMENTS_THROUGH, **DEFAULT_CHAIN_OPTIONS)
    coarse = chain_grid(strut, DEFAULT_ELEMENTS_THROUGH, **{**PROTOTYPE_CHAIN_OPTIONS, "strut_refinement": 1})
    assert coarse.active.sum() * 4 < fine.active.sum()
    refined = chain_grid(strut, DEFAULT_ELEMENTS_THROUGH, **PROTOTYPE_CHAIN_OPTIONS)
    assert refined.active.sum() == PROTOTYPE_CHAIN_OPTIONS["strut_refinement"] ** 3 * coarse.active.sum()
    for name in ("L1", "D1"):
        segment = _segment(name, 0)
        assert (cells_through(segment, DEFAULT_ELEMENTS_THROUGH, PROTOTYPE_CHAIN_OPTIONS["slenderness"], even=True)
                >= cells_through(segment, 7, DEFAULT_CHAIN_OPTIONS["slenderness"]))
        grid = chain_grid(segment, DEFAULT_ELEMENTS_THROUGH, **PROTOTYPE_CHAIN_OPTIONS)
        accurate = chain_grid(segment, 7, **DEFAULT_CHAIN_OPTIONS)
        # the end face x = 0 of the end block: no fine cell at its rim (the accurate grid's
        # is edge_aspect neck cells wide)
        assert np.diff(grid.x)[0] > 2 * np.diff(accurate.x)[0]


@pytest.mark.slow
def test_the_former_fast_grid_misses_it_on_the_stubby_leaf():
    # that the checks above can fail: the prototype's grid until session 15 (session 13's:
    # 6 through for every leaf, side cells of 3 neck cells) left L1's leaf-1 segment 0.85 %
    # off (measured 0.848 %)
    from flexcal.fem.mesh_mapped_chain import FAST_CHAIN_OPTIONS

    # 0.005: the goal the accurate grid and the prototype's meet (the tests above)
    assert _largest_error("L1", 0, elements_through_thickness=6, **FAST_CHAIN_OPTIONS) > 0.005


def test_even_through_gives_every_leaf_segment_both_mirror_planes():
    # session 24's knob (docs/meshing.md, "Session 24: the prototype's grid for tied cuts"): an
    # odd number of cells through the leaves is raised by one, so the core has a line at its
    # middle and a D leaf segment (7 through at 7 asked for) is condensed on a quarter, not a half
    from flexcal.fem.mesh_mapped_chain import (COARSE_PROTOTYPE_CHAIN_OPTIONS, PROTOTYPE_CHAIN_OPTIONS,
                                               mapped_mesh_chain_mirror_part)

    d1, l1, strut = _segment("D1", 0), _segment("L1", 0), _segment("L1", 2)
    assert cells_through(d1, 7, 5.5, even=True) == 8 and cells_through(d1, 7, 5.5) == 7
    assert cells_through(l1, 7, 5.5, even=True) == 8  # already even: as it was
    assert cells_through(l1, 7, None, even=True) == 8  # n as given, then made even
    assert cells_through(strut, 7, 5.5, even=True) == 7  # no leaf: its section has both planes anyway
    # the prototype's grid: 10 through the L leaves (l / t = 5: 7 x 6.25 / 5 = 8.75 -> 9 -> 10), 8 through D's
    grid_options = PROTOTYPE_CHAIN_OPTIONS
    assert [cells_through(s, 7, grid_options["slenderness"], even=True) for s in (l1, d1)] == [10, 8]
    coarse = COARSE_PROTOTYPE_CHAIN_OPTIONS  # without even_through: a D leaf segment on a half
    assert mapped_mesh_chain_mirror_part(d1, elements_through_thickness=7, **coarse)[1] == (2,)
    assert mapped_mesh_chain_mirror_part(d1, elements_through_thickness=7,
                                         **{**coarse, "even_through": True})[1] == (1, 2)
    grid = chain_grid(d1, 7, **{**coarse, "even_through": True})
    core = CHAINS["D1"].thickness_1 + 2 * CHAINS["D1"].fillet
    # 1e-9: the core's end line, exact to round-off
    assert np.count_nonzero(np.abs(grid.p) < 0.5 * core * (1 - 1e-9)) + 1 == 8 and np.any(grid.p == 0.0)


def test_strut_refinement_splits_only_the_cells_of_strut_segments():
    from flexcal.fem.mesh_mapped_chain import COARSE_PROTOTYPE_CHAIN_OPTIONS as base

    strut, leaf = _segment("L1", 2), _segment("D1", 1)
    finer = {**base, "strut_refinement": 2}
    coarse, fine = chain_grid(strut, 7, **base), chain_grid(strut, 7, **finer)
    for a, b in ((coarse.x, fine.x), (coarse.p, fine.p), (coarse.q, fine.q)):
        assert len(b) - 1 == 2 * (len(a) - 1) and np.array_equal(b[::2], a)  # nested: every cell halved
    same, kept = chain_grid(leaf, 7, **base), chain_grid(leaf, 7, **finer)
    assert all(np.array_equal(u, v) for u, v in ((same.x, kept.x), (same.p, kept.p), (same.q, kept.q)))
    with pytest.raises(ValueError, match="strut_refinement"):
        chain_grid(strut, 7, **{**base, "strut_refinement": 1.5})
