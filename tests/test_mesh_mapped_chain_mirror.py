"""The prototype's segments condensed on their mirror part (session 17,
``mapped_mesh_chain_mirror_part`` + ``mirrored_chain_stiffness``, docs/meshing.md "The
prototype's grid, mirrored"): the same 12 x 12 as the whole mirrored mesh condensed at once,
repeatable to the bit, and across thread counts."""

import numpy as np
import pytest

from flexcal.fem.condense import MIRROR_PARITY, chain_stiffness, mirrored_chain_stiffness
from flexcal.fem.mesh import TetMesh
# the grid until session 24 (no even_through): its odd cells through the D leaves give the one-plane case
from flexcal.fem.mesh_mapped_chain import COARSE_PROTOTYPE_CHAIN_OPTIONS as PROTOTYPE_CHAIN_OPTIONS
from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain_mirror_part
from flexcal.fem.solve import solver_threads
from flexcal.geometry.exact import end_planes, reference_points
from flexcal.geometry.params import STEEL, ChainSegment, reference_mechanism
from flexcal.validation.prototype.segments import section_nodes

CHAINS = {c.name: c.chain for c in reference_mechanism().chains}
# a P2 tet mirrored: corners 1 and 2 swapped (positive volume again), its edges renumbered
FLIP = [0, 2, 1, 3, 6, 5, 4, 7, 9, 8]


def _segment(name: str, k: int) -> ChainSegment:
    nodes = section_nodes(CHAINS[name])
    return ChainSegment(chain=CHAINS[name], x_start=float(nodes[k]), x_end=float(nodes[k + 1]))


def _mirrored(mesh: TetMesh, axis: int) -> TetMesh:
    """The mesh and its mirror image about the plane (axis) = 0, the plane's nodes shared."""
    on = mesh.nodes[:, axis] == 0.0
    image = mesh.nodes[~on].copy()
    image[:, axis] *= -1.0
    index = np.where(on, np.arange(len(mesh.nodes)), len(mesh.nodes) + np.cumsum(~on) - 1)
    return TetMesh(np.vstack([mesh.nodes, image]), np.vstack([mesh.tets, index[mesh.tets][:, FLIP]]))


def _condense(segment, mesh, axes):
    planes, points = end_planes(segment), reference_points(segment)
    return mirrored_chain_stiffness(mesh, STEEL, planes["A"], points["A"], planes["B"], points["B"], axes)


@pytest.mark.parametrize("name, k, axes", [("L1", 0, (1, 2)), ("D1", 0, (2,)), ("D1", 1, (1,)), ("L1", 2, (1, 2))])
def test_the_mirror_part_condenses_to_the_whole_mirrored_mesh(name, k, axes):
    segment = _segment(name, k)
    part, found = mapped_mesh_chain_mirror_part(segment, elements_through_thickness=3, **PROTOTYPE_CHAIN_OPTIONS)
    # L leaves: 4 cells through their core at n = 3 (even, a line at 0 on both section axes);
    # D leaves: 3 (odd), so only the leaf's width axis is a mirror
    assert found == axes
    for a in axes:
        assert part.nodes[:, a].min() == 0.0
    whole = part
    for a in axes:
        whole = _mirrored(whole, a)
    planes, points = end_planes(segment), reference_points(segment)
    expected = chain_stiffness(whole, STEEL, planes["A"], points["A"], planes["B"], points["B"])
    got = _condense(segment, part, axes)
    scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    # 1e-9: two direct solves of the same equations in other elimination orders (measured
    # 3e-12 to 6e-12 of the diagonal geometric mean at n = 3, 2e-11 to 5e-11 at n = 7)
    assert np.max(np.abs(got - expected) / scale) < 1e-9
    # entries between parity classes are zero: one class never moves another's masters
    parity = np.stack([np.tile(MIRROR_PARITY[a], 2) for a in axes])
    same_class = np.all(parity[:, :, None] == parity[:, None, :], axis=0)
    assert np.all(got[~same_class] == 0.0)
    # ... and the whole mesh's are zero to round-off (1e-9 as above)
    assert np.max(np.abs(expected[~same_class]) / scale[~same_class]) < 1e-9


def test_the_mirror_condensation_is_repeatable_and_thread_independent():
    segment = _segment("L1", 1)
    part, axes = mapped_mesh_chain_mirror_part(segment, elements_through_thickness=3, **PROTOTYPE_CHAIN_OPTIONS)
    again, _ = mapped_mesh_chain_mirror_part(segment, elements_through_thickness=3, **PROTOTYPE_CHAIN_OPTIONS)
    assert np.array_equal(part.nodes, again.nodes) and np.array_equal(part.tets, again.tets)
    with solver_threads(1):
        one = _condense(segment, part, axes)
        one_again = _condense(segment, part, axes)
    with solver_threads(2):
        two = _condense(segment, part, axes)
    assert np.array_equal(one, one_again)  # the same bits on the same thread count
    # 1e-9: issue 26's bound across thread counts (measured 4e-14 on a whole leaf segment)
    np.testing.assert_allclose(two, one, rtol=1e-9, atol=1e-9 * np.abs(one).max())


def test_mirror_axes_are_checked():
    segment = _segment("L1", 0)
    part, _ = mapped_mesh_chain_mirror_part(segment, elements_through_thickness=3, **PROTOTYPE_CHAIN_OPTIONS)
    with pytest.raises(ValueError, match="axes"):
        _condense(segment, part, (3,))
    shifted = TetMesh(part.nodes + np.array([0.0, 1e-3, 0.0]), part.tets)
    with pytest.raises(ValueError, match="non-negative side"):
        _condense(segment, shifted, (1,))


def test_the_refined_mirror_part_is_the_quarter_of_the_refined_grid():
    # the nested levels of the chain reference study (refinement r) condensed on their quarter:
    # the part's nodes are exactly the refined whole mesh's nodes on y >= 0, z >= 0
    from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain

    segment = _segment("D1", 0)
    options = dict(elements_through_thickness=2, refinement=2, side_aspect=3.0, slenderness=None)
    part, axes = mapped_mesh_chain_mirror_part(segment, **options)
    whole, _ = mapped_mesh_chain(segment, measure=False, **options)
    assert axes == (1, 2)
    quarter = whole.nodes[(whole.nodes[:, 1] >= 0.0) & (whole.nodes[:, 2] >= 0.0)]
    assert np.array_equal(np.unique(part.nodes, axis=0), np.unique(quarter, axis=0))
    with pytest.raises(ValueError, match="refinement"):
        mapped_mesh_chain_mirror_part(segment, elements_through_thickness=2, refinement=0)


# table1's as-built L1 chain 1 (seed of the scenario's own draw), rounded: the mapper's own grid of
# its first segment has 35 x 18 x 20 cells against the nominal's 33 x 16 x 20 (more cells through)
AS_BUILT_MOVES = {"l": -0.0125, "w": -0.0962, "a": -0.0847, "t1": 0.0906, "t2": 0.0629}


@pytest.mark.parametrize("index", [0, 1, 2])
def test_a_part_on_its_templates_cells_has_the_templates_connectivity_and_its_own_geometry(index):
    """``template_grid``: an as-built L1 segment meshed on its nominal segment's cells has the
    nominal mesh's tets node for node, its own volume (to the quadratic arcs' 5e-5, as its own
    mesh) and every feature of its own (piece ends, fillet ends, leaf cores and widths) on a grid
    line; a part of another design is refused."""
    from flexcal.fem.mesh_mapped_chain import (_section_features, _x_features, chain_grid, template_grid)
    from flexcal.fem.mesh_quality import corner_volumes
    from flexcal.geometry.exact import exact_volume
    from flexcal.validation.prototype.cut_fields import interface_segments
    from flexcal.validation.runs.model_correction import moved_chain

    options = {**PROTOTYPE_CHAIN_OPTIONS, "even_through": True}
    nominal_chain = reference_mechanism().chains[0].chain
    nominal = interface_segments(nominal_chain, 5)[index][0]
    part = interface_segments(moved_chain(nominal_chain, AS_BUILT_MOVES), 5)[index][0]
    own, _ = mapped_mesh_chain_mirror_part(part, elements_through_thickness=7, **options)
    template, axes = mapped_mesh_chain_mirror_part(nominal, elements_through_thickness=7, **options)
    mesh, mesh_axes = mapped_mesh_chain_mirror_part(part, elements_through_thickness=7, template=nominal, **options)
    assert mesh_axes == axes and np.array_equal(mesh.tets, template.tets)
    if index < 2:  # the leaf segments: the mapper's own grid of the as-built part has other cells
        assert own.tets.shape != template.tets.shape
    assert corner_volumes(mesh.nodes, mesh.tets).min() > 0
    # curved P2 on the fillet cylinders: off only by the quadratic arcs (5e-5, as the test above)
    assert abs(mesh.volume * 2 ** len(axes) / exact_volume(part) - 1.0) < 5e-5
    grid = template_grid(part, nominal, 7, **options)
    for lines, features in ((grid.x, _x_features(part)), (grid.p, _section_features(part, 1)),
                            (grid.q, _section_features(part, 2))):
        # each feature a grid line, to the interpolation's round-off (1e-12 of the part's 50 mm)
        assert np.abs(features[:, None] - lines[None, :]).min(axis=1).max() < 1e-12 * 0.05
    same, _ = mapped_mesh_chain_mirror_part(nominal, elements_through_thickness=7, template=nominal, **options)
    assert np.array_equal(same.nodes, template.nodes)  # its own template: the mapper's grid itself
    strut = interface_segments(nominal_chain, 5)[2][0]
    if index < 2:
        with pytest.raises(ValueError, match="not one design"):
            template_grid(part, strut, 7, **options)
