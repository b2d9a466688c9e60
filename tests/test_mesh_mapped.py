"""The deterministic mapped mesher of single hinges (flexcal.fem.mesh_mapped)."""

import numpy as np
import pytest

from flexcal.fem.mesh_mapped import MAX_MAPPED_DOF, mapped_grid, mapped_mesh_part, mapped_mesh_supported
from flexcal.geometry.params import STEEL, CircularNotchHinge, LeafHinge
from flexcal.geometry.solids import hinge_solid

MM = 1e-3
NOTCH = CircularNotchHinge(radius=5 * MM, thickness=1 * MM, width=10 * MM, block_length=5 * MM)
LEAF = LeafHinge(length=20 * MM, thickness=4 * MM, width=40 * MM, fillet=6 * MM, block_length=10 * MM)


@pytest.mark.parametrize("hinge", [NOTCH, LEAF], ids=["notch", "leaf"])
def test_same_part_same_mesh_valid_and_on_the_surfaces(hinge):
    part = hinge_solid(hinge)
    mesh, report = mapped_mesh_part(part, elements_through_thickness=2)
    again, _ = mapped_mesh_part(hinge_solid(hinge), elements_through_thickness=2)
    assert np.array_equal(mesh.nodes, again.nodes) and np.array_equal(mesh.tets, again.tets)
    assert report.min_jacobian_ratio > 0  # no folded quadratic element
    assert report.n_straight_mid == 0  # the isoparametric map folds nothing on these two
    # P2 tets with mid-nodes on the exact arcs: the volume is off only by the quadratic
    # approximation of each arc segment (measured 7.8e-5 notch, 3.2e-5 leaf at n = 3)
    assert abs(report.volume_error) < 1e-3
    assert report.max_surface_deviation < 1e-9 * hinge.total_length  # every boundary node on its surface
    assert report.options["mesher"] == "mapped"


def test_working_rotation_against_the_closed_form():
    from flexcal.validation.reports.fem import compare_hinge

    result = compare_hinge(NOTCH, STEEL, elements_through_thickness=3, mesher="mapped")
    # 3-D FEM vs Euler-Bernoulli integral at t/R = 0.2: published agreement 0.1-9.4 %,
    # measured +0.6 % with this mesh and +1.0 % with fTetWild meshes (docs/reliability.md)
    assert result.compliance_fem[5, 5] == pytest.approx(result.compliance_analytic[5, 5], rel=0.05)


def test_grid_is_graded_symmetric_and_ends_on_the_part():
    x, eta, z = mapped_grid(LEAF, 3)
    assert np.allclose(x, -x[::-1], rtol=0, atol=1e-15)  # symmetric about the neck (round-off only)
    assert x[0] == pytest.approx(-LEAF.total_length / 2) and x[-1] == pytest.approx(LEAF.total_length / 2)
    assert len(eta) == 4 and z[0] == -LEAF.width / 2 and z[-1] == LEAF.width / 2
    assert np.all(np.diff(x) > 0)


def test_what_it_does_not_mesh():
    high_blocks = LeafHinge(length=20 * MM, thickness=4 * MM, width=40 * MM, fillet=6 * MM, block_length=10 * MM,
                            block_height=50 * MM)
    assert not mapped_mesh_supported(high_blocks)
    with pytest.raises(ValueError, match="tetwild"):
        mapped_mesh_part(hinge_solid(high_blocks))
    wide = CircularNotchHinge(radius=5 * MM, thickness=0.05 * MM, width=200 * MM, block_length=5 * MM)
    with pytest.raises(ValueError, match=f"limit {MAX_MAPPED_DOF:,}"):
        mapped_mesh_part(hinge_solid(wide), elements_through_thickness=3)
    with pytest.raises(ValueError, match=">= 1"):
        mapped_mesh_part(hinge_solid(NOTCH), elements_through_thickness=0.5)
