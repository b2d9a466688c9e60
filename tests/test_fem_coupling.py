"""Rigid couplings and prescribed DOFs by elimination."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from flexcal.fem.coupling import (
    RigidCoupling,
    coupling_map,
    eliminate_dofs,
    mesh_size,
    rigid_body_modes,
    select_plane_nodes,
)
from flexcal.fem.structured import box_tet_mesh
from flexcal.geometry.frames import skew

MESH = box_tet_mesh(0.04, 0.01, 0.02, 4, 2, 2)


def test_plane_selection_finds_the_face():
    face = select_plane_nodes(MESH, ((0.04, 0.0, 0.0), (1.0, 0.0, 0.0)))
    assert face.size == (2 * 2 + 1) * (2 * 2 + 1)
    np.testing.assert_allclose(MESH.nodes[face, 0], 0.04)
    # a tilted normal of the same plane finds the same face (normal is normalised)
    same = select_plane_nodes(MESH, ((0.04, 0.003, 0.0), (-2.0, 0.0, 0.0)))
    np.testing.assert_array_equal(face, same)
    # cells are 10 x 5 x 10 mm, 6 tets each: every tet has one edge along each axis (5, 10,
    # 10 mm), two face diagonals (5 sqrt 5 or 10 sqrt 2 mm) and the 15 mm body diagonal, so
    # half of all edges are <= 10 mm and the shortest of the other half is 5 sqrt 5 mm: the
    # median of an even count is their mean, (10 + 5 sqrt 5) / 2 = 10.590 mm
    expected = 0.5 * (0.010 + 0.005 * np.sqrt(5.0))
    assert mesh_size(MESH) == pytest.approx(expected, rel=1e-12)  # round-off of linspace nodes and norms only


def test_plane_selection_errors_say_what_to_do():
    with pytest.raises(ValueError, match="must be a face of the mesh"):
        select_plane_nodes(MESH, ((0.05, 0.0, 0.0), (1.0, 0.0, 0.0)))
    with pytest.raises(ValueError, match="non-zero"):
        select_plane_nodes(MESH, ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))


def test_coupling_transform_moves_slaves_rigidly():
    rng = np.random.default_rng(0)
    face_a = select_plane_nodes(MESH, ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    face_b = select_plane_nodes(MESH, ((0.04, 0.0, 0.0), (1.0, 0.0, 0.0)))
    point_b = np.array([0.05, 0.001, -0.002])  # off the face: an arm
    cmap = coupling_map(
        len(MESH.nodes),
        MESH.nodes,
        [RigidCoupling(nodes=face_a, reference_point=np.zeros(3), fixed=True), RigidCoupling(nodes=face_b, reference_point=point_b)],
    )
    assert cmap.master_dofs[0] is None
    n_free = len(MESH.nodes) - face_a.size - face_b.size
    assert cmap.n_reduced == 3 * n_free + 6
    u_r = np.zeros(cmap.n_reduced)
    twist = rng.standard_normal(6) * 1e-3
    u_r[cmap.master_dofs[1]] = twist
    u = (cmap.transform @ u_r).reshape(-1, 3)
    expected = twist[:3] + np.cross(twist[3:], MESH.nodes[face_b] - point_b)
    # transform entries are 1 and lever arms: round-off of ~2e-5 m (ulp 3e-21); rtol=0 (default 1e-7 hid it)
    np.testing.assert_allclose(u[face_b], expected, rtol=0, atol=1e-18)
    assert np.all(u[face_a] == 0.0)


def test_overlapping_couplings_are_rejected():
    face = select_plane_nodes(MESH, ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    with pytest.raises(ValueError, match="share slave nodes"):
        coupling_map(
            len(MESH.nodes),
            MESH.nodes,
            [RigidCoupling(nodes=face, reference_point=np.zeros(3)), RigidCoupling(nodes=face[:3], reference_point=np.zeros(3))],
        )


def test_rigid_body_modes_are_rigid():
    modes = rigid_body_modes(MESH.nodes, origin=np.zeros(3)).reshape(-1, 3, 6)
    theta = np.array([0.1, -0.2, 0.3])
    # round-off of ~1e-2 m products; rtol=0 (default 1e-7 hid it)
    np.testing.assert_allclose(modes[:, :, 3:] @ theta, np.cross(theta, MESH.nodes), rtol=0, atol=1e-16)
    np.testing.assert_allclose(skew(theta) @ np.ones(3), np.cross(theta, np.ones(3)))


def test_eliminate_dofs_solves_with_prescribed_values():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((8, 8))
    K = A @ A.T + 8 * np.eye(8)
    u_true = rng.standard_normal(8)
    f = K @ u_true
    dofs = np.array([1, 4, 6])
    K_ff, rhs, free = eliminate_dofs(sp.csr_matrix(K), f, dofs, u_true[dofs])
    # K = A A^T + 8 I is well conditioned: round-off only
    np.testing.assert_allclose(np.linalg.solve(K_ff.toarray(), rhs), u_true[free], rtol=1e-12)
