"""Tet meshing: the TetMesh contract, sizing, snapping onto exact surfaces, pytetwild.

Snapping is tested first on structured meshes whose boundary nodes were pushed off the
surfaces at random (fast, no pytetwild); then one coarse pytetwild mesh of the reference
notch hinge is checked end to end. Heavier meshes are marked slow.
"""

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from flexcal.fem.mesh_projection import boundary_faces, project_onto, tangent_pairs
from flexcal.fem.mesh_quality import EDGES, corner_volumes, p2_volumes, radius_ratio
from flexcal.fem.mesh_sizing import kuhn_tets, sizing_grid, target_size
from flexcal.fem.mesh_snap import boundary_node_sets, snap_to_part
from flexcal.fem.mesh_tets import TetMesh, linear_to_quadratic
from flexcal.geometry.exact import exact_volume, thin_sections
from flexcal.geometry.params import CircularNotchHinge, FlexureChain, LeafHinge
from flexcal.geometry.surfaces import CylinderPatch, boundary_patches

NOTCH = CircularNotchHinge(radius=5e-3, thickness=1e-3, width=10e-3, block_length=5e-3)
LEAF = LeafHinge(length=20e-3, thickness=4e-3, width=40e-3, fillet=6e-3, block_length=10e-3)
STEPPED = LeafHinge(length=20e-3, thickness=4e-3, width=12e-3, fillet=0.0, block_length=6e-3, block_height=10e-3)


# ----------------------------------------------------------------------------------------
# structured test meshes


def grid_mesh(xs, ys, zs):
    """Linear tet mesh of a tensor grid (positive volumes)."""
    nodes = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)
    tets = kuhn_tets((len(xs), len(ys), len(zs)))
    flip = corner_volumes(nodes, tets) < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return nodes, tets


def compact(nodes, tets):
    used, inverse = np.unique(tets, return_inverse=True)
    return nodes[used], inverse.reshape(-1, 4)


def notch_mesh(n_thickness=4):
    """Mapped mesh of NOTCH: y = s * h(x), s in [-1/2, 1/2]; boundary nodes exact."""
    R, e = NOTCH.radius, NOTCH.block_length
    phi = np.linspace(-np.pi / 2, np.pi / 2, 33)  # equal arcs of the notch circle
    xs = np.concatenate([np.linspace(-R - e, -R, 4)[:-1], R * np.sin(phi), np.linspace(R, R + e, 4)[1:]])
    nodes, tets = grid_mesh(xs, np.linspace(-0.5, 0.5, n_thickness + 1), np.linspace(-5e-3, 5e-3, 6))
    (section,) = thin_sections(NOTCH)
    x = nodes[:, 0]
    height = np.where(np.abs(x) < R, section.thickness(x), NOTCH.height)
    nodes[:, 1] *= height
    return nodes, tets


def stepped_leaf_mesh():
    """STEPPED (plain leaf between taller blocks): grid through every edge, cells
    outside the part removed. Sharp convex and concave edges, no curves."""
    l, t, e, h, w = STEPPED.length, STEPPED.thickness, STEPPED.block_length, STEPPED.height, STEPPED.width
    xs = np.unique(np.concatenate([np.linspace(-l / 2 - e, -l / 2, 4), np.linspace(-l / 2, l / 2, 9),
                                   np.linspace(l / 2, l / 2 + e, 4)]))
    ys = np.unique(np.concatenate([np.linspace(-h / 2, -t / 2, 3), np.linspace(-t / 2, t / 2, 4),
                                   np.linspace(t / 2, h / 2, 3)]))
    nodes, tets = grid_mesh(xs, ys, np.linspace(-w / 2, w / 2, 5))
    c = nodes[tets].mean(axis=1)
    keep = ~((np.abs(c[:, 0]) < l / 2) & (np.abs(c[:, 1]) > t / 2))
    return compact(nodes, tets[keep])


def perturb_boundary(nodes, tets, size, seed=0):
    """Push boundary nodes off the surfaces by up to ``size`` [m] in every direction."""
    rng = np.random.default_rng(seed)
    out = nodes.copy()
    b = np.unique(boundary_faces(tets))
    out[b] += rng.uniform(-size, size, (len(b), 3))
    assert corner_volumes(out, tets).min() > 0
    return out


# ----------------------------------------------------------------------------------------
# TetMesh and quadratic nodes


def test_tetmesh_contract():
    nodes, tets4 = grid_mesh([0, 1.0], [0, 1.0], [0, 1.0])
    nodes10, tets10, edges = linear_to_quadratic(nodes, tets4)
    mesh = TetMesh(nodes10, tets10)  # positional, as the FEM builds it
    assert (mesh.n_nodes, mesh.n_tets, mesh.n_dof) == (len(nodes10), 6, 3 * len(nodes10))
    np.testing.assert_array_equal(mesh.corner_tets, tets4)
    assert mesh.volume == pytest.approx(1.0, rel=1e-14)  # unit cube as six tets: exact but for float64 round-off
    with pytest.raises(ValueError):
        mesh.nodes[0, 0] = 5.0  # read-only
    with pytest.raises(ValueError, match=r"\(n_tets, 10\)"):
        TetMesh(nodes=nodes, tets=tets4)
    with pytest.raises(ValueError, match="non-positive volume"):
        TetMesh(nodes=nodes10, tets=tets10[:, [0, 2, 1, 3, 6, 5, 4, 7, 9, 8]])
    with pytest.raises(ValueError, match="outside"):
        TetMesh(nodes=nodes10, tets=tets10 + 100)


def test_mid_nodes_are_shared_edge_midpoints():
    nodes, tets4 = grid_mesh(np.linspace(0, 1, 3), np.linspace(0, 2, 4), np.linspace(0, 1, 3))
    nodes10, tets10, edges = linear_to_quadratic(nodes, tets4)
    for m, (a, b) in enumerate(EDGES):
        np.testing.assert_array_equal(nodes10[tets10[:, 4 + m]], 0.5 * (nodes10[tets10[:, a]] + nodes10[tets10[:, b]]))
    # one node per edge: (sorted corner pair) -> mid-node is a function and one-to-one
    pairs = np.sort(tets10[:, EDGES], axis=2).reshape(-1, 2)
    mids = tets10[:, 4:].ravel()
    table = {}
    for pair, mid in zip(map(tuple, pairs), mids):
        assert table.setdefault(pair, mid) == mid
    assert len(set(table.values())) == len(table) == len(edges) == len(nodes10) - len(nodes)


def test_unique_rows_equals_numpy_unique():
    from flexcal.fem.mesh_quality import unique_rows

    rows = np.random.default_rng(0).integers(0, 40, (2000, 3))
    fast = unique_rows(rows, 40, return_inverse=True, return_counts=True)
    plain = np.unique(rows, axis=0, return_index=True, return_inverse=True, return_counts=True)
    for a, b in zip(fast, plain):
        np.testing.assert_array_equal(np.ravel(a), np.ravel(b))


def test_kuhn_grid_is_conforming():
    nodes, tets = grid_mesh(np.linspace(0, 3, 4), np.linspace(0, 2, 3), np.linspace(0, 1, 2))
    # 3 x 2 x 1 box: exact but for round-off in the sum
    assert corner_volumes(nodes, tets).sum() == pytest.approx(6.0, rel=1e-14)
    # a conforming mesh has exactly the surface triangles of the box: 2 per cell face
    assert len(boundary_faces(tets)) == 2 * 2 * (3 * 2 + 3 * 1 + 2 * 1)
    assert radius_ratio(nodes, tets).min() > 0.71  # every Kuhn tet of a cubic cell has the radius ratio 0.7174


# ----------------------------------------------------------------------------------------
# sizing


def test_target_size_fine_in_the_neck_coarse_elsewhere():
    n, h_max = 3, 2.5e-3
    t, R = NOTCH.thickness, NOTCH.radius
    size = target_size(NOTCH, np.array([[0, 0, 0], [0, 0.4e-3, 4e-3], [2e-3, 0, 0], [-9e-3, 0, 0],
                                        [0, 3e-3, 0]]), n_through=n, h_max=h_max)
    t_2mm = t + 2 * R - 2 * np.sqrt(R**2 - 4e-6)
    # the same closed form (circular notch profile / n): round-off only
    np.testing.assert_allclose(size[:3], [t / n, t / n, t_2mm / n], rtol=1e-12)
    assert size[3] == h_max  # in a block
    # inside the notch's cut-out (outside the material) the size grows with the distance
    # closed form as above: round-off only
    np.testing.assert_allclose(size[4], t / n + 0.5 * (3e-3 - t / 2), rtol=1e-12)


def test_sizing_grid_covers_the_part_with_positive_tets():
    points, tets, values = sizing_grid(FlexureChain(length=0.15, thickness_1=3e-3, thickness_2=3e-3),
                                       n_through=3, h_max=0.02)
    assert corner_volumes(points, tets).min() > 0
    # min = t / n = 3 mm / 3 exactly (round-off); max = h_max
    assert values.min() == pytest.approx(1e-3, rel=1e-12) and values.max() == pytest.approx(0.02)
    assert points[:, 0].min() < 0 and points[:, 0].max() > 0.15  # the grid reaches beyond both ends of the 0.15 m chain


# ----------------------------------------------------------------------------------------
# projection


def test_project_onto_edge_of_plane_and_cylinder():
    patches = {p.name: p for p in boundary_patches(NOTCH)}
    top, notch = patches["block_free:+y"], patches["hinge:+ynotch"]
    point = np.array([[5.02e-3, 5.47e-3, 1e-3]])
    edge = project_onto(point, [top, notch])
    assert top.surface_distance(edge)[0] == 0.0
    # exact edge point: round-off of 5 mm coordinates (1 ulp = 0.9e-18 m)
    assert notch.surface_distance(edge)[0] < 1e-18
    # a few ulp of the 5.5 mm coordinate (1 ulp = 0.9e-18 m)
    np.testing.assert_allclose(edge, [[5e-3, 5.5e-3, 1e-3]], atol=1e-17)


def test_tangent_pairs_are_leaf_to_fillet_only():
    names = lambda params: {tuple(sorted((boundary_patches(params)[i].name, boundary_patches(params)[j].name)))
                            for i, j in tangent_pairs(boundary_patches(params))}
    assert names(NOTCH) == set()  # the notch meets the block top at a right angle
    leaf = names(LEAF)
    assert ("hinge:+y", "hinge:+yfillet0") in leaf and ("hinge:-y", "hinge:-yfillet1") in leaf
    assert len(leaf) == 4


def test_snap_restores_sharp_edges_exactly():
    """Plain leaf between taller blocks (convex and concave edges, corners): after
    snapping, every surface is exact and so is the volume (all faces planar)."""
    nodes, tets = stepped_leaf_mesh()
    tol = 0.1e-3
    off = perturb_boundary(nodes, tets, 0.3 * tol)
    mesh, measured = snap_to_part(STEPPED, off, tets, tolerance=tol)
    assert measured["volume_error_raw"] != 0.0  # the perturbation did change the volume
    assert abs(measured["volume_error"]) < 1e-13  # planar faces: exact up to round-off
    assert measured["max_surface_deviation"] < 1e-18  # vertices snapped exactly (1 ulp of 10 mm = 1.7e-18 m)
    assert measured["end_plane_deviation"] == 0.0
    assert (measured["n_demoted"], measured["n_unsnapped"], measured["n_unassigned"]) == (0, 0, 0)
    # nodes on three faces (vertices of the solid) are back exactly where they were
    half = np.array([STEPPED.total_length / 2, STEPPED.height / 2, STEPPED.width / 2])
    # picks the box corners: far above linspace round-off, far below the 0.3 mm grid step
    corners = np.nonzero(np.all(np.isclose(np.abs(nodes), half, rtol=0, atol=1e-15), axis=1))[0]
    assert len(corners) == 8
    # vertex = intersection of three planes: bit-exact (1 ulp of 16 mm = 3.5e-18 m)
    np.testing.assert_allclose(mesh.nodes[corners], nodes[corners], rtol=0, atol=1e-18)
    (neck,) = measured["necks"]
    # flat leaf faces snapped onto their planes: round-off only
    assert neck.thickness_mesh == pytest.approx(STEPPED.thickness, rel=1e-14)


def test_snap_puts_corner_and_mid_nodes_on_the_notch():
    nodes, tets = notch_mesh()
    tol = 20e-6
    off = perturb_boundary(nodes, tets, 0.3 * tol, seed=1)
    mesh, measured = snap_to_part(NOTCH, off, tets, tolerance=tol)
    patches, node_sets = boundary_node_sets(NOTCH, nodes, tets, tol)
    notch_ids = {k for k, p in enumerate(patches) if isinstance(p, CylinderPatch)}
    on_notch = np.array([i for i, ks in node_sets.items() if notch_ids.intersection(ks)])
    radius = np.hypot(mesh.nodes[on_notch, 0], np.abs(mesh.nodes[on_notch, 1]) - NOTCH.height / 2)
    # corner nodes projected onto the cylinder: round-off only
    np.testing.assert_allclose(radius, NOTCH.radius, rtol=1e-14)
    # mid-nodes of boundary edges on the notch lie on the circle too (not on the chord)
    mids = mesh.tets[:, 4:][np.isin(mesh.tets[:, EDGES[:, 0]], on_notch)
                            & np.isin(mesh.tets[:, EDGES[:, 1]], on_notch)]
    p = mesh.nodes[np.unique(mids)]
    on_circle = np.abs(np.hypot(p[:, 0], np.abs(p[:, 1]) - NOTCH.height / 2) - NOTCH.radius) < 1e-12
    assert on_circle.mean() > 0.5  # boundary edges; the rest are interior chords between notch nodes
    assert measured["max_surface_deviation"] < 1e-17  # projection onto the circle: a few ulp of 5 mm coordinates
    assert measured["end_plane_deviation"] == 0.0
    (neck,) = measured["necks"]
    # neck nodes lie exactly on the notch circles: round-off only (relative error)
    assert abs(neck.thickness_error) < 1e-12
    # Arcs of pi/32 rad are exact to 5e-8 R as quadratics, but the mapped cells next to the
    # blocks are 24 um wide and 2.5 mm tall: curving their edges would fold them, so they
    # stay straight (n_straight_mid). Their chords cut <= R (1 - cos(pi/64)) = 6 um over
    # <= 2 cells x 4 ends x 0.5 mm x 10 mm of notch surface: <= 0.16 mm^3 = 1.1e-4 of the volume.
    assert 0 < measured["n_straight_mid"] < 0.1 * len(on_notch)
    # chord bound derived above; the raw mesh is off by more
    assert abs(measured["volume_error"]) < 1.1e-4 < abs(measured["volume_error_raw"])
    interior = np.setdiff1d(np.arange(len(nodes)), np.unique(boundary_faces(tets)))
    assert np.abs(mesh.nodes[interior] - off[interior]).max() > 0  # the interior followed (morph)


def test_snap_without_projection_keeps_the_nodes():
    nodes, tets = notch_mesh()
    off = perturb_boundary(nodes, tets, 5e-6, seed=2)
    mesh, measured = snap_to_part(NOTCH, off, tets, tolerance=20e-6, project=False)
    np.testing.assert_array_equal(mesh.nodes[: len(off)], off)
    # unprojected, the mid-nodes sit on chords: at least as far off as the corners
    assert measured["max_surface_deviation"] >= measured["max_surface_deviation_raw"] > 1e-6


# ----------------------------------------------------------------------------------------
# pytetwild


def _box_surface(size=(0.02, 0.01, 0.005)):
    """A closed, outward-oriented triangulation of a box: 8 vertices, 12 triangles."""
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) * size
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.int32)
    return corners, faces


def test_fTetWild_mesh_repeats_for_a_seed_and_thread_count():
    """fTetWild draws from std::random_device; the meshing child serves those draws from
    flexcal.fem._entropy. The same input and seed give the same mesh, with 1 thread or 2;
    another seed gives another mesh (so the equality is the seed's doing: unseeded, three
    calls gave three meshes, docs/reliability.md). No "ran unseeded" warning."""
    import warnings

    from flexcal.fem.tetwild_process import (
        MESHER_SEED,
        mesher_is_seeded,
        tetrahedralize_in_child,
    )

    assert mesher_is_seeded()  # built by setup.sh's pip install (needs a C compiler)
    vertices, faces = _box_surface()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        runs = [tetrahedralize_in_child(vertices, faces, edge_length_fac=0.1, quiet=True, num_threads=threads)
                for threads in (1, 2)]
        other = tetrahedralize_in_child(vertices, faces, edge_length_fac=0.1, quiet=True, num_threads=1,
                                        seed=MESHER_SEED + 1)
    (nodes, tets), (nodes_2, tets_2) = runs
    assert np.array_equal(nodes, nodes_2) and np.array_equal(tets, tets_2)
    assert not (nodes.shape == other[0].shape and np.array_equal(nodes, other[0]))
    for bad in (-1, 1.5, True, 2**64):
        with pytest.raises(ValueError, match="seed"):
            tetrahedralize_in_child(vertices, faces, seed=bad)


def test_runs_away_past_25_times_the_sizing_fields_vertex_count():
    from flexcal.fem.tetwild_process import expected_vertices, runs_away

    # a unit cube, h = 0.1 everywhere (6 Kuhn tets): 1 / 0.1^3 = 1000 expected vertices
    nodes, tets = grid_mesh(np.array([0.0, 1.0]), np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    # six tet volumes and a cube of h: exact but for round-off
    assert expected_vertices(nodes, tets, np.full(len(nodes), 0.1)) == pytest.approx(1000.0, rel=1e-12)
    assert not runs_away(8_900, 1000.0)  # the largest normal run measured: 8.9x
    assert not runs_away(25_000, 1000.0) and runs_away(25_001, 1000.0)


def test_a_run_past_the_watch_is_stopped_and_the_next_seed_meshes(monkeypatch):
    """The runaway path of ``tetrahedralize_in_child`` in ~2 s (the real runaway below is slow):
    the first seed's child is watched against an expected count of 1e-3 vertices, so its first
    reported pass is past 25x and it is stopped mid-run; seed + 1, unwatched, gives the mesh."""
    from flexcal.fem import tetwild_process

    outcomes = []
    run = tetwild_process._mesh_in_child

    def watched_first(arrays, options, expected):
        first = options["__seed__"] == tetwild_process.MESHER_SEED
        outcomes.append((options["__seed__"], run(arrays, options, 1e-3 if first else None)))
        return outcomes[-1][1]

    monkeypatch.setattr(tetwild_process, "_mesh_in_child", watched_first)
    vertices, faces = _box_surface()
    nodes, tets = tetwild_process.tetrahedralize_in_child(vertices, faces, edge_length_fac=0.1, quiet=True,
                                                          num_threads=1)
    seed = tetwild_process.MESHER_SEED
    assert [s for s, _ in outcomes] == [seed, seed + 1]
    assert outcomes[0][1] is None and np.array_equal(outcomes[1][1][0], nodes) and len(tets) > 0


# ~60 s of a real fTetWild runaway (fTetWild is an option since the mapped mesher became the default,
# issue 26); test_a_run_past_the_watch_is_stopped_and_the_next_seed_meshes runs the same path in the default run
@pytest.mark.slow
def test_a_seed_whose_run_runs_away_is_left_for_the_next(monkeypatch):
    """tests/data/tetwild_runaway.npz: the fTetWild input (surface, sizing field, options)
    of a 36 mm block segment of the mount on which MESHER_SEED's run grows without end
    (still meshing after 17 min in the FEM grid run, 2026-11-24). The child is stopped
    past 25x the sizing field's vertex count (~20 s here) and seed + 1 gives the mesh (~6 s)."""
    import json

    from flexcal.fem import tetwild_process

    with np.load(Path(__file__).parent / "data" / "tetwild_runaway.npz") as data:
        arrays = {name: np.array(data[name]) for name in data.files}
    options = json.loads(str(arrays.pop("__options__")))
    seed = options.pop("__seed__")
    assert seed == tetwild_process.MESHER_SEED
    outcomes = []
    run = tetwild_process._mesh_in_child

    def recorded(arrays, options, expected):
        outcomes.append((options["__seed__"], run(arrays, options, expected)))
        return outcomes[-1][1]

    monkeypatch.setattr(tetwild_process, "_mesh_in_child", recorded)
    nodes, tets = tetwild_process.tetrahedralize_in_child(arrays.pop("vertices"), arrays.pop("faces"),
                                                          **arrays, **options)
    assert [s for s, _ in outcomes] == [seed, seed + 1]
    assert outcomes[0][1] is None and np.array_equal(outcomes[1][1][0], nodes)
    assert 1000 < len(nodes) < 10000  # measured 3 754 nodes; the runaway passed 30 000


def test_surface_triangles_come_in_one_order_whatever_the_cad_order():
    """fTetWild's mesh depends on the order of its input, and OCCT lists a fused solid's
    faces in an order that changes between processes, with 1-ulp differences in shared
    vertices. _canonical_order gives one triangulation for any vertex order, triangle
    order, triangle rotation and 1-ulp perturbation of the vertices."""
    from flexcal.fem.mesh import _canonical_order

    rng = np.random.default_rng(7)
    vertices = rng.uniform(-0.05, 0.05, (60, 3))
    faces = np.array([rng.choice(60, 3, replace=False) for _ in range(100)])
    reference = _canonical_order(vertices, faces)
    for _ in range(5):
        order = rng.permutation(60)
        shuffled = np.empty_like(vertices)
        shuffled[order] = np.nextafter(vertices, rng.choice([-1.0, 1.0], vertices.shape))
        rotated = np.roll(order[faces], rng.integers(3), axis=1)[rng.permutation(100)]
        result = _canonical_order(shuffled, rotated)
        assert np.array_equal(result[0], reference[0]) and np.array_equal(result[1], reference[1])
    # the same triangles: each keeps its orientation (a cyclic turn, not a reflection)
    v, f = reference
    order = np.lexsort(v.T[::-1])
    assert np.array_equal(order, np.arange(60))  # sorted by (x, y, z)
    rank = np.argsort(np.lexsort(np.round(vertices * 2.0**40).T[::-1]))  # old index -> new
    assert {tuple(t) for t in f} == {tuple(np.roll(t, -np.argmin(t))) for t in rank[faces]}
    # moved by at most half the 2**-40 m rounding step
    assert np.abs(v - vertices[np.argsort(rank)]).max() <= 2.0**-41


@pytest.fixture(scope="module")
def coarse_notch(tmp_path_factory):
    pytest.importorskip("pytetwild")
    from flexcal.fem.mesh import mesh_part
    from flexcal.geometry.solids import hinge_solid

    folder = tmp_path_factory.mktemp("cwd")
    previous = os.getcwd()
    os.chdir(folder)
    try:
        mesh, report = mesh_part(hinge_solid(NOTCH), elements_through_thickness=2)
    finally:
        os.chdir(previous)
    return mesh, report, folder


def test_pytetwild_leaves_nothing_in_the_working_directory(coarse_notch):
    _, _, folder = coarse_notch
    assert list(Path(folder).iterdir()) == []


def test_coarse_notch_mesh_is_valid_and_exact_where_it_matters(coarse_notch):
    mesh, report, _ = coarse_notch
    assert isinstance(mesh, TetMesh) and mesh.tets.shape[1] == 10
    assert corner_volumes(mesh.nodes, mesh.tets).min() > 0
    assert report.min_jacobian_ratio > 0  # curved elements are not folded either
    assert (report.n_nodes, report.n_tets) == (mesh.n_nodes, mesh.n_tets)
    length = NOTCH.total_length
    for point, normal in (((-length / 2, 0, 0), (-1, 0, 0)), ((length / 2, 0, 0), (1, 0, 0))):
        distance = (mesh.nodes - np.array(point)) @ np.array(normal, float)
        face = np.abs(distance) < 1e-3 * NOTCH.thickness  # well inside an element
        assert face.sum() >= 3
        # end-face nodes set onto the plane: measured 0; 1e-15 = a few ulp of 10 mm
        assert np.abs(distance[face]).max() <= 1e-15 * length
    assert report.end_plane_deviation <= 1e-15 * length  # as above: measured 0
    # fTetWild alone leaves the surface tens of um off; snapped, it is exact to round-off
    assert report.max_surface_deviation_raw > 1e-6
    # projection onto planes/cylinders: measured 9e-17 x length (1 ulp); 1e-15 leaves 10x
    assert report.max_surface_deviation < 1e-15 * length
    # what remains is the quadratic interpolation of arcs of <= 0.5 rad (curvature cap):
    # radial error <= 1.2e-4 R over the notch surfaces (2 pi R b) -> 1.3e-4 of the volume
    assert abs(report.volume_error) < 1.3e-4
    # the same quadratic-arc bound as volume_error above
    assert mesh.volume == pytest.approx(exact_volume(NOTCH), rel=1.3e-4)
    (neck,) = report.necks
    # neck nodes lie on the notch circles: measured 9e-16 (round-off); 1e-13 leaves 100x
    assert abs(neck.thickness_error) < 1e-13
    assert neck.thickness_min == pytest.approx(NOTCH.thickness, rel=1e-13)  # as above: measured 2.6e-15


def test_coarse_notch_has_the_requested_elements_through_the_neck(coarse_notch):
    _, report, _ = coarse_notch
    (neck,) = report.necks
    # fTetWild splits edges longer than 4/3 and collapses those shorter than 4/5 of the
    # target, so the median edge is within [0.75, 1.33] x target: elements across >= 0.75 n
    assert neck.elements_across >= 0.75 * report.options["elements_through_thickness"]
    assert neck.tets_crossed >= 2


def test_coarse_notch_mid_nodes(coarse_notch):
    mesh, report, _ = coarse_notch
    n_corner = report.n_corner_nodes
    mids = mesh.nodes[mesh.tets[:, 4:]]
    chord = 0.5 * (mesh.nodes[mesh.tets[:, EDGES[:, 0]]] + mesh.nodes[mesh.tets[:, EDGES[:, 1]]])
    offset = np.linalg.norm(mids - chord, axis=2)
    curved = offset > 1e-12 * NOTCH.total_length
    # only mid-nodes on the notch surfaces leave their chord, and by at most the sagitta
    # of an arc of <= 0.5 rad: R (1 - cos 0.25) = 0.031 R
    assert curved.any()
    p = mids[curved]
    on_circle = np.hypot(p[:, 0], np.abs(p[:, 1]) - NOTCH.height / 2)
    # mid-nodes projected onto the circle: measured 3e-16 (round-off); 1e-14 leaves 30x
    np.testing.assert_allclose(on_circle, NOTCH.radius, rtol=1e-14)
    assert offset.max() < 0.031 * NOTCH.radius  # sagitta bound derived above (measured 0.009 R)
    assert mesh.tets[:, 4:].min() >= n_corner


def test_mesh_part_rejects_bad_options():
    from flexcal.fem.mesh import mesh_part
    from flexcal.geometry.solids import hinge_solid

    part = hinge_solid(NOTCH)
    for options, word in ((dict(elements_through_thickness=0), "elements_through_thickness"),
                          (dict(max_element_size=-1.0), "max_element_size"),
                          (dict(epsilon=0.5), "epsilon"), (dict(grading=0), "grading")):
        with pytest.raises(ValueError, match=word):
            mesh_part(part, **options)


# ----------------------------------------------------------------------------------------
# slow: reference leaf hinge and driving chain


@pytest.mark.slow
@pytest.mark.parametrize("params, n", [(LEAF, 3), (FlexureChain(length=0.150, thickness_1=0.003, thickness_2=0.003), 2)],
                         ids=["leaf", "driving_chain"])
def test_reference_parts_mesh_exactly(params, n, tmp_path, monkeypatch):
    from flexcal.fem.mesh import mesh_part
    from flexcal.geometry.solids import chain_solid, hinge_solid

    monkeypatch.chdir(tmp_path)
    part = chain_solid(params) if isinstance(params, FlexureChain) else hinge_solid(params)
    mesh, report = mesh_part(part, elements_through_thickness=n)
    assert list(tmp_path.iterdir()) == []
    size = float(np.ptp(mesh.nodes, axis=0).max())
    # end-face nodes set onto the plane: round-off only (measured 0 on the coarse notch)
    assert report.end_plane_deviation <= 1e-12 * size
    # projection onto the exact surfaces: round-off only (1e-12 not measured tighter on these slow meshes)
    assert report.max_surface_deviation < 1e-12 * size
    assert report.min_jacobian_ratio > 0
    # fillet arcs of <= 0.5 rad: radial error <= 1.2e-4 a on the fillet surfaces
    assert abs(report.volume_error) < 1.2e-4
    assert len(report.necks) == len(thin_sections(params))
    for neck in report.necks:
        # nodes next to the tangent line of a flat leaf face and its fillet sit on the
        # nearer of the two, which differ by dx^2 / 2a there: measured <= 1e-6 of t
        assert abs(neck.thickness_error) < 1e-5
        assert 0.75 * n <= neck.elements_across <= 1.34 * n  # fTetWild's 4/5 .. 4/3 band
    assert p2_volumes(mesh.nodes, mesh.tets).min() > 0


_PARENT_MESHING_THE_RUNAWAY = """
import json, sys
import numpy as np
from flexcal.fem import tetwild_process
with np.load(sys.argv[1]) as data:
    arrays = {name: np.array(data[name]) for name in data.files}
options = json.loads(str(arrays.pop("__options__")))
options.pop("__seed__")
tetwild_process.tetrahedralize_in_child(arrays.pop("vertices"), arrays.pop("faces"), **arrays, **options)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_mesher_child_dies_with_its_parent_and_its_folder_is_removed_later(tmp_path):
    """A Dask worker ended by its nanny runs no ``finally``: its fTetWild child went on
    meshing after the command had stopped, and its temporary folder stayed. The child now
    dies with its parent (PR_SET_PDEATHSIG) and the folder, named by its owner, is removed
    by the next call (``remove_stale_mesher_folders``). The parent here meshes the runaway
    input (tests/data/tetwild_runaway.npz: ~20 s in fTetWild) and is killed with SIGKILL."""
    import psutil

    from flexcal.fem import tetwild_process

    parent = subprocess.Popen([sys.executable, "-c", _PARENT_MESHING_THE_RUNAWAY,
                               str(Path(__file__).parent / "data" / "tetwild_runaway.npz")],
                              env={**os.environ, "TMPDIR": str(tmp_path)}, stdin=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60  # the parent's imports on a loaded 2-core machine
        children = []
        while not children and time.monotonic() < deadline and parent.poll() is None:
            children = psutil.Process(parent.pid).children()
            time.sleep(0.05)
        assert len(children) == 1 and "flexcal.fem.tetwild_process" in " ".join(children[0].cmdline())
        child = children[0]
        time.sleep(2.0)  # past its imports (0.3 s idle), inside fTetWild, which runs ~20 s on this input
        assert child.is_running() and child.status() != psutil.STATUS_ZOMBIE
        parent.kill()
        parent.wait()
        # the kernel kills the child as its parent dies; 5 s is room for a loaded machine to
        # reap it (measured: gone within the first 0.1 s poll)
        gone, alive = psutil.wait_procs([child], timeout=5)
        assert alive == [] and gone == [child]
    finally:
        parent.kill()
        parent.wait()
    folders = [p.name for p in tmp_path.iterdir() if p.name.startswith("flexcal-tetwild-")]
    assert len(folders) == 1 and (tmp_path / folders[0] / "in.npz").is_file()  # left by the killed parent
    live = tmp_path / f"flexcal-tetwild-{tetwild_process.owner_tag()}-abcd1234"  # this process's: kept
    live.mkdir()
    assert tetwild_process.remove_stale_mesher_folders(tmp_path) == folders
    assert sorted(p.name for p in tmp_path.iterdir()) == [live.name]
