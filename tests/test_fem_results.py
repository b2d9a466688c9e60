"""VTU output, nodal stress recovery and the deformed-shape PNG."""

from __future__ import annotations

import numpy as np
import pytest

from flexcal.fem.condense import hinge_displacement, solve_hinge
from flexcal.fem.results import nodal_stress, render_deformed_png, von_mises, write_vtu
from flexcal.fem.structured import box_tet_mesh
from flexcal.geometry.params import Material

STEEL = Material()
MESH = box_tet_mesh(0.05, 0.01, 0.01, 5, 1, 1, origin=(0.0, -0.005, -0.005))


def test_von_mises_of_simple_states():
    assert von_mises(np.array([100.0, 0, 0, 0, 0, 0])) == pytest.approx(100.0)
    assert von_mises(np.array([0.0, 0, 0, 0, 0, 50.0])) == pytest.approx(50.0 * np.sqrt(3))
    assert von_mises(np.array([7.0, 7.0, 7.0, 0, 0, 0])) == pytest.approx(0.0, abs=1e-12)  # hydrostatic
    batch = np.random.default_rng(0).standard_normal((4, 3, 6))
    np.testing.assert_allclose(von_mises(batch), [[von_mises(s) for s in row] for row in batch])


def test_nodal_stress_of_uniaxial_tension():
    strain = 1e-4
    u = np.zeros_like(MESH.nodes)
    u[:, 0] = strain * MESH.nodes[:, 0]
    u[:, 1] = -STEEL.poisson_ratio * strain * MESH.nodes[:, 1]
    u[:, 2] = -STEEL.poisson_ratio * strain * MESH.nodes[:, 2]
    stress = nodal_stress(MESH, STEEL, u)
    expected = np.zeros(6)
    expected[0] = STEEL.youngs_modulus * strain
    # linear field: exact up to round-off of the gradients
    np.testing.assert_allclose(stress, np.broadcast_to(expected, stress.shape), atol=1e-9 * expected[0])


def test_vtu_round_trip(tmp_path):
    """Pure bending with nu = 0 (an exactly represented quadratic field): the written
    stress is the beam's sigma_xx = -M y / I at every node."""
    import pyvista as pv

    material = Material(poisson_ratio=0.0)
    solution = solve_hinge(MESH, material, ((0, 0, 0), (1, 0, 0)), ((0.05, 0, 0), (1, 0, 0)), (0.05, 0, 0))
    moment = 2.0  # [N m] about z
    u = hinge_displacement(solution, [0.0, 0.0, 0.0, 0.0, 0.0, moment])
    path = write_vtu(MESH, tmp_path / "beam.vtu", u, material)
    assert [p.name for p in tmp_path.iterdir()] == ["beam.vtu"]
    grid = pv.read(path)
    assert set(np.unique(grid.celltypes)) == {pv.CellType.QUADRATIC_TETRA}
    np.testing.assert_allclose(grid.points, MESH.nodes)
    np.testing.assert_array_equal(grid.cells.reshape(-1, 11)[:, 1:], MESH.tets)
    np.testing.assert_allclose(grid.point_data["displacement"], u)
    inertia = 0.01**4 / 12
    expected = -moment * MESH.nodes[:, 1] / inertia
    peak = np.abs(expected).max()  # 12 MPa
    # exact field: round-off of the solve (1e-11 relative) amplified by differentiation
    np.testing.assert_allclose(grid.point_data["stress"][:, 0], expected, atol=1e-7 * peak)
    # as above: the exact stress is uniaxial
    np.testing.assert_allclose(grid.point_data["stress"][:, 1:], 0.0, atol=1e-7 * peak)
    # von Mises combines the six components, each to 1e-7 of the peak
    np.testing.assert_allclose(grid.point_data["von_mises"], np.abs(expected), atol=1e-6 * peak)
    with pytest.raises(ValueError, match=".vtu"):
        write_vtu(MESH, tmp_path / "beam.vtk", u)
    with pytest.raises(ValueError, match="displacement has shape"):
        write_vtu(MESH, tmp_path / "bad.vtu", u[:-1])


def test_render_png(tmp_path):
    u = np.zeros_like(MESH.nodes)
    u[:, 1] = 1e-6 * (MESH.nodes[:, 0] / 0.05) ** 2
    path = render_deformed_png(MESH, u, tmp_path / "deformed.png", material=STEEL)
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert [p.name for p in tmp_path.iterdir()] == ["deformed.png"]


def test_render_mesh_png(tmp_path):
    from flexcal.fem.results import render_mesh_png

    path = render_mesh_png(MESH, tmp_path / "mesh.png")
    data = path.read_bytes()
    # a real picture (PNG signature, more than a blank frame compresses to) and no temp file left
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert [p.name for p in tmp_path.iterdir()] == ["mesh.png"]
    with pytest.raises(ValueError, match=".png"):
        render_mesh_png(MESH, tmp_path / "mesh.jpg")
