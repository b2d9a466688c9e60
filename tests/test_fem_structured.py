"""Structured P2 tet meshes: boxes and mapped notch hinges."""

from __future__ import annotations

import numpy as np
import pytest

from flexcal.fem.elements import REFERENCE_NODES, TET_14POINT, affine_elements, element_volumes, jacobians, shape_gradients
from flexcal.fem.structured import box_tet_mesh, grid_tet_mesh, notch_height, notch_hinge_tet_mesh
from flexcal.geometry.params import CircularNotchHinge

HINGE = CircularNotchHinge(radius=5e-3, thickness=1e-3, width=10e-3, block_length=5e-3)


def _boundary_faces(tets: np.ndarray) -> np.ndarray:
    """Corner triples of faces used by exactly one tet."""
    faces = np.sort(np.concatenate([tets[:, [0, 1, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 3]], tets[:, [1, 2, 3]]]), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    assert counts.max() <= 2, "a face shared by more than two tets: the mesh is not a manifold"
    return unique[counts == 1]


def test_box_mesh_counts_volume_and_midpoints():
    nx, ny, nz = 3, 2, 4
    mesh = box_tet_mesh(0.03, 0.02, 0.04, nx, ny, nz, origin=(1.0, 2.0, 3.0))
    assert mesh.tets.shape == (6 * nx * ny * nz, 10)
    assert len(mesh.nodes) == (2 * nx + 1) * (2 * ny + 1) * (2 * nz + 1)
    volumes = element_volumes(mesh.nodes[mesh.tets])
    assert (volumes > 0).all()
    assert volumes.sum() == pytest.approx(0.03 * 0.02 * 0.04, rel=1e-13)  # round-off of a sum
    assert affine_elements(mesh.nodes[mesh.tets]).all()
    np.testing.assert_allclose(mesh.nodes.min(axis=0), [1.0, 2.0, 3.0])
    assert len(np.unique(mesh.tets)) == len(mesh.nodes)  # every node used


def test_box_mesh_is_conforming():
    """Interior faces are shared by two tets, so the boundary faces are exactly the
    4 triangles per square of the box surface."""
    nx, ny, nz = 2, 3, 2
    mesh = box_tet_mesh(1.0, 1.0, 1.0, nx, ny, nz)
    boundary = _boundary_faces(mesh.tets)
    assert len(boundary) == 2 * 2 * (nx * ny + ny * nz + nx * nz)
    # all boundary corners on the box surface
    points = mesh.nodes[boundary.ravel()]
    on_surface = np.isclose(points, 0.0) | np.isclose(points, 1.0)
    assert on_surface.any(axis=1).all()


def test_graded_grid_and_errors():
    mesh = grid_tet_mesh(np.array([0.0, 0.1, 0.3, 0.7]), np.array([0.0, 1.0]), np.array([0.0, 0.5, 1.0]))
    # box 0.7 x 1 x 1 as tets: round-off only
    assert element_volumes(mesh.nodes[mesh.tets]).sum() == pytest.approx(0.7, rel=1e-13)
    with pytest.raises(ValueError, match="strictly increasing"):
        grid_tet_mesh(np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="positive integer"):
        box_tet_mesh(1, 1, 1, 0, 1, 1)


def _exact_hinge_volume(hinge: CircularNotchHinge) -> float:
    return hinge.width * (hinge.total_length * hinge.height - np.pi * hinge.radius**2)


def test_notch_mesh_geometry():
    curved = notch_hinge_tet_mesh(HINGE, 2)
    straight = notch_hinge_tet_mesh(HINGE, 2, curved=False)
    exact = _exact_hinge_volume(HINGE)
    v_curved = element_volumes(curved.nodes[curved.tets]).sum()
    v_straight = element_volumes(straight.nodes[straight.tets]).sum()
    # curved P2 edges follow the circle: measured 7e-5 (error left by the few straightened
    # tets next to the blocks); the polygonal version is ~40x worse (chords cut the notch)
    assert abs(v_curved / exact - 1) < 2e-4
    assert abs(v_straight / exact - 1) > 10 * abs(v_curved / exact - 1)
    # the neck: nodes at x = 0 span exactly the thickness t
    neck = np.abs(curved.nodes[:, 0]) < 1e-12
    # neck nodes at +-t/2 from the profile: round-off only
    assert np.ptp(curved.nodes[neck, 1]) == pytest.approx(HINGE.thickness, rel=1e-12)
    # boundary nodes lie on the profile |y| = h(x)/2 or on block faces
    np.testing.assert_allclose(curved.nodes[:, 0].min(), -HINGE.total_length / 2, rtol=1e-14)
    # every tet's map is valid at the nodes and at the 14 quadrature points
    points = np.vstack([REFERENCE_NODES, TET_14POINT.points])
    det = np.linalg.det(jacobians(curved.nodes[curved.tets], shape_gradients(points)))
    assert (det > 0).all()
    # most notch tets are curved (the fold fix only touches a few next to the blocks)
    assert (~affine_elements(curved.nodes[curved.tets])).mean() > 0.3


def test_notch_height_profile():
    x = np.array([0.0, 3e-3, 5e-3, 7e-3])
    # the closed-form profile: round-off only
    np.testing.assert_allclose(notch_height(HINGE, x), [1e-3, 11e-3 - 2 * 4e-3, 11e-3, 11e-3], rtol=1e-12)
