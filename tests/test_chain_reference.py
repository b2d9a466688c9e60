"""The mapped chain mesher's Richardson limit on the prototype's leaf segments against an
independent reference: 27-node hexahedra on their own multi-block grid
(flexcal.fem.reference_hex_chain; issue 26 "Verification", docs/meshing.md "Independent
reference: Q2 hexahedra (session 18)")."""

import functools

import numpy as np
import pytest

from flexcal.fem.reference_hex_chain import hex27_segment_stiffness, leaf_height, segment_grid
from flexcal.fem.reference_hex_element import full_stiffness, grid_nodes
from flexcal.geometry.exact import BoxPiece, exact_volume, pieces
from flexcal.geometry.params import STEEL
from flexcal.validation.reports.chain_reference import AGREEMENT, compare, mapped_stiffness, segment

from helpers import rigid_energy_and_stretch_volume_error

PROTOTYPE_GOAL = 5e-3  # issue 26: the default mesh within 0.5 % of the converged stiffness


def _leaf(part):
    return next(p for p in pieces(part) if not isinstance(p, BoxPiece))


def test_segment_element_keeps_rigid_motions_and_linear_fields_exact():
    # isoparametric Q2 on the blocks and the mapped leaf core: a rigid motion stores no
    # energy, a uniform strain the energy of the meshed volume, which converges on the exact one
    part = segment("L1")
    errors = []
    for r in (1, 2, 3):
        K, nodes = full_stiffness(segment_grid(part, refinement=r), STEEL)
        rigid, volume_error = rigid_energy_and_stretch_volume_error(K, nodes, exact_volume(part), STEEL)
        # round-off: measured <= 2.3e-17 of the sum of the magnitudes; 1e-13 leaves 4000x
        assert rigid < 1e-13
        errors.append(volume_error)
    # measured 9.6e-4, 1.4e-4, 4.3e-5 (r = 1, 2, 3): the fillets' quadratic geometry converges
    # at h^2.8-2.9 (cells uniform in the arc angle); 2.5 per level is faster than h^2 at r 2 -> 3
    assert 0 < errors[2] < errors[1] / 2.5 < errors[0] / 2.5 ** 2


def test_segment_profile_is_the_leaf():
    # the reference writes the leaf height itself; the geometry package's leaf agrees
    part = segment("D1")
    leaf = _leaf(part)
    x = np.linspace(leaf.x0 - 1e-3, leaf.x1 + 1e-3, 81)
    # two formulas: at the leaf's ends (d -> a) sqrt(a^2 - d^2) turns the round-off of d^2
    # (~1e-19 m^2) into ~3e-10 m (measured 2.9e-10 m); 1e-9 m is 1.7e-7 of the fillet
    np.testing.assert_allclose(leaf_height(leaf, x), leaf.local_thickness(x), rtol=0, atol=1e-9)


def test_segment_grid_keeps_the_material_and_conforms_at_the_block_faces():
    part = segment("L1")
    leaf = _leaf(part)
    grid = segment_grid(part, refinement=2)
    xm = 0.5 * (grid.x[1:] + grid.x[:-1])
    pm, zm = 0.5 * (grid.p[1:] + grid.p[:-1]), 0.5 * (grid.z[1:] + grid.z[:-1])
    in_leaf = (xm > leaf.x0) & (xm < leaf.x1)
    assert grid.active[~in_leaf].all()
    footprint = (np.abs(pm) < grid.core_half)[:, None] & (np.abs(zm) < leaf.half_width)[None, :]
    assert np.array_equal(grid.active[in_leaf], np.broadcast_to(footprint, grid.active[in_leaf].shape))
    nodes, _ = grid_nodes(grid)
    # one node per point (conforming, no duplicates at the block faces), every node in the part
    assert np.unique(np.round(nodes / 1e-9).astype(np.int64), axis=0).shape[0] == nodes.shape[0]
    here = (nodes[:, 0] > leaf.x0) & (nodes[:, 0] < leaf.x1)
    # 1e-12 m: the map puts the leaf's surface nodes on the exact height to round-off
    assert np.all(np.abs(nodes[here, 1]) <= 0.5 * leaf.local_thickness(nodes[here, 0]) + 1e-12)
    # 1e-12 m: the width lines are the leaf's side faces exactly
    assert np.all(np.abs(nodes[here, 2]) <= leaf.half_width + 1e-12)


def test_segment_stiffness_is_symmetric_with_the_six_rigid_modes():
    part = segment("D1")
    k, _ = hex27_segment_stiffness(part, refinement=1)
    length = part.x_end - part.x_start
    for mode in np.eye(6):
        u, theta = mode[:3], mode[3:]
        rigid = np.concatenate([u, theta, u + np.cross(theta, [length, 0.0, 0.0]), theta])
        # in energy units (each row by sqrt(K_ii), against sqrt(sum_j K_jj v_j^2)): round-off of
        # K_mm - K_im^T K_ii^-1 K_im, which cancels the tied blocks' far larger stiffness;
        # measured 1.1e-13 to 4.1e-10 (the rotations); 1e-8 leaves 25x
        diagonal = np.abs(np.diag(k))
        # 1e-8: the measured round-off above, 25x
        assert np.all(np.abs(k @ rigid) / np.sqrt(diagonal) <= 1e-8 * np.sqrt(diagonal @ rigid**2))
    # symmetrised (0.5 (K + K^T)): equal to round-off, 1e-12 of the largest entry
    np.testing.assert_allclose(k, k.T, rtol=0, atol=1e-12 * np.abs(k).max())


def test_segment_with_a_leaf_thin_along_z_is_computed_turned_and_turned_back():
    # D1 [m1, s0] (leaf 2 thin along z): the reference turns it a quarter about x onto the
    # y-thin grid and the 12 x 12 back; against the mapped nested level r = 2 of the segment
    # as it stands. Both are coarse and too stiff: their own errors against their limits are
    # <= 2.0 % (mapped r = 2) and <= 1.0 % (Q2 r = 2) on L1 [0, m1] (docs/meshing.md), so 2 %
    # of the diagonal geometric mean bounds their difference (measured 0.52 %); a wrong turn
    # swaps the compliant z and the stiff y direction (a factor 5.6) or flips coupling signs
    part = segment("D1", 1)
    k, _ = hex27_segment_stiffness(part, refinement=2)
    mapped, _ = mapped_stiffness(part, 2)
    size = np.sqrt(np.outer(np.abs(np.diag(k)), np.abs(np.diag(k))))
    # 2 %: the bound on the two coarse levels' difference argued above
    assert np.all(np.abs(k - mapped) <= 0.02 * size)
    # the leaf's compliant direction is z: K[uy,uy] / K[uz,uz] measured 5.6; 3 tells it from 1 / 5.6
    assert k[2, 2] < k[1, 1] / 3


ENTRIES = ["K[uxA,uxA]", "K[uxA,uxB]", "K[uyA,uyA]", "K[uyA,rzA]", "K[uyA,uyB]", "K[uyA,rzB]", "K[uzA,uzA]",
           "K[uzA,ryA]", "K[uzA,uzB]", "K[uzA,ryB]", "K[rxA,rxA]", "K[rxA,rxB]", "K[ryA,ryA]", "K[ryA,uzB]",
           "K[ryA,ryB]", "K[rzA,rzA]", "K[rzA,uyB]", "K[rzA,rzB]", "K[uxB,uxB]", "K[uyB,uyB]", "K[uyB,rzB]",
           "K[uzB,uzB]", "K[uzB,ryB]", "K[rxB,rxB]", "K[ryB,ryB]", "K[rzB,rzB]"]


@functools.cache
def _leaf_segment_rows(chain: str) -> dict:
    # mapped nested at 2 through, r = 2, 3, 4; Q2 hexes r = 2, 3, 4 (19k / 62k / 143k DOF);
    # the prototype's mesh. L1: the whole nested grids (62k / 198k / 455k DOF), D1: their
    # quarters (28k / 85k / 192k DOF per parity class; D1's whole r = 4, 727k DOF, needs
    # more than 8 GB). Measured (2026-11-28, load 7-13): L1 87 s CPU, 5 min 15 s wall, 4.2 GB
    # peak; D1 62 s CPU, 2 min 47 s wall at load ~10, 1.5 GB peak
    rows = compare(chain, None, (2, 3, 4), (2, 3, 4), prototype=True, mirrored=chain == "D1")
    return {row[0]: row for row in rows}


CASES = [(chain, entry) for chain in ("L1", "D1") for entry in ENTRIES]


@pytest.mark.slow
@pytest.mark.parametrize("chain, entry", CASES)
def test_leaf_segment_mapped_limit_within_a_tenth_of_a_percent_of_the_hex27_reference(chain, entry):
    rows = _leaf_segment_rows(chain)
    assert sorted(rows) == sorted(ENTRIES)  # the dominant entries of the 12 x 12
    name, _, mapped, _, reference, uncertainty, diff, *_ = rows[entry]
    assert abs(diff) <= AGREEMENT, (f"{chain} {name}: mapped limit {mapped:.6e} is {100 * diff:+.3f} % from the "
                                    f"Q2-hex reference {reference:.6e} (+- {100 * uncertainty / abs(reference):.3f} %)")


@pytest.mark.slow
@pytest.mark.parametrize("chain, entry", CASES)
def test_prototype_segment_mesh_within_half_a_percent_of_the_hex27_reference(chain, entry):
    # the goal for the default mesh: 0.5 % of the converged value, here the reference's limit
    name, *_, prototype, _ = _leaf_segment_rows(chain)[entry]
    assert abs(prototype) <= PROTOTYPE_GOAL, f"{chain} {name}: the prototype's mesh is {100 * prototype:+.3f} % off"


@functools.cache
def _l1_second_segment_rows() -> dict:
    # L1 [m1, s0] (leaf 2 thin along z, the reference turned): mapped nested at 2 through on
    # the mirror quarters, r = 4, 5, 6 (137k / 259k / 438k DOF); Q2 hexes r = 3..6 (78k..603k DOF).
    # At session 18's levels (mapped r = 2, 3, 4) K[rzA,rzB] missed by +0.124 %: its mapped
    # levels are not asymptotic there. Measured (2026-11-28, session 19, load 2-6): every entry
    # within 0.1 % (K[rzA,rzB] +0.097 % at the finest level, which stands in for its limit);
    # the test run 7 min 41 s wall idle, 9.0 GB peak (docs/meshing.md, "Session 19")
    rows = compare("L1", None, (4, 5, 6), (3, 4, 5, 6), prototype=True, mirrored=True, index=1)
    return {row[0]: row for row in rows}


@pytest.mark.slow
@pytest.mark.parametrize("entry", ENTRIES)
def test_second_leaf_segment_of_l1_mapped_within_a_tenth_of_a_percent_of_the_hex27_reference(entry):
    rows = _l1_second_segment_rows()
    assert sorted(rows) == sorted(ENTRIES)  # the same 26 dominant entries as on [0, m1]
    name, _, mapped, _, reference, uncertainty, diff, *_ = rows[entry]
    assert abs(diff) <= AGREEMENT, (f"L1 [m1, s0] {name}: mapped limit {mapped:.6e} is {100 * diff:+.3f} % from the "
                                    f"Q2-hex reference {reference:.6e} (+- {100 * uncertainty / abs(reference):.3f} %)")


@pytest.mark.slow
@pytest.mark.parametrize("entry", ENTRIES)
def test_prototype_second_leaf_segment_of_l1_within_half_a_percent_of_the_hex27_reference(entry):
    # session 19 measured the torsion K[rx,rx] at +0.506 % on 6 cells per fillet arc; with 8
    # (session 20) +0.476 %, every other entry <= 0.458 % (docs/meshing.md, "Session 20")
    name, *_, prototype, _ = _l1_second_segment_rows()[entry]
    assert abs(prototype) <= PROTOTYPE_GOAL, f"L1 [m1, s0] {name}: the prototype's mesh is {100 * prototype:+.3f} % off"


FINE_GOAL = 3e-3  # session 24: the leaf segments' own error must leave room for the tied cuts (~0.06-0.12 %)


@pytest.mark.slow
@pytest.mark.parametrize("chain, index", [("L1", 0), ("L1", 1), ("D1", 0), ("D1", 1)],
                         ids=["L1 [0, m1]", "L1 [m1, s0]", "D1 [0, m1]", "D1 [m1, s0]"])
def test_fine_prototype_grid_within_three_tenths_of_a_percent_of_the_hex27_reference(chain, index):
    # PROTOTYPE_CHAIN_OPTIONS (since session 25; docs/meshing.md, "Session 24"): every dominant entry within
    # 0.3 % of the Q2-hex limit of levels r = 2, 3, 4 (measured 0.278 / 0.266 / 0.279 / 0.283 %;
    # against the limit of r = 4, 5, 6 (or 3, 4, 5) 0.265 / 0.271 / 0.276 / 0.271 %), where the
    # prototype's grid until session 24 misses it in torsion (measured 0.456 / 0.472 / 0.470 / 0.500 %)
    from flexcal.fem.convergence import dominant_entries
    from flexcal.fem.mesh_mapped_chain import COARSE_PROTOTYPE_CHAIN_OPTIONS, PROTOTYPE_CHAIN_OPTIONS
    from flexcal.validation.reports.chain_cuts import segment_stiffness
    from flexcal.validation.reports.chain_reference import reference_stiffness
    from flexcal.validation.reports.fem import DOMINANT_FRACTION
    from flexcal.validation.reports.hinge_reference import reference_limit

    part = segment(chain, index)
    levels = [2, 3, 4]
    values = np.array([reference_stiffness(part, r)[0] for r in levels])
    _, limit, _, _ = reference_limit(levels, values)
    mask = dominant_entries(values[-1], DOMINANT_FRACTION)

    def error(options):
        k = segment_stiffness(part, 7.0, options)
        return np.abs(k - limit)[mask] / np.abs(limit[mask])

    fine, coarse = error(PROTOTYPE_CHAIN_OPTIONS), error(COARSE_PROTOTYPE_CHAIN_OPTIONS)
    assert fine.max() <= FINE_GOAL, f"{chain} [{index}]: the prototype's grid is {100 * fine.max():.3f} % off"
    assert coarse.max() > FINE_GOAL  # that the check can fail: the grid until session 24, the torsion
