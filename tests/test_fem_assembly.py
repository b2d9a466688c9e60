"""Global stiffness: symmetry, rigid-body null space, patch tests, body force."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from flexcal.fem.assembly import assemble_body_force, assemble_stiffness, check_mesh, element_dofs
from flexcal.fem.coupling import eliminate_dofs, rigid_body_modes
from flexcal.fem.elements import EDGES, affine_elements, elasticity_matrix, element_stiffness, element_volumes, lame_parameters
from flexcal.fem.results import nodal_stress
from flexcal.fem.solve import solve_spd
from flexcal.fem.structured import StructuredTetMesh, box_tet_mesh
from flexcal.geometry.params import Material

STEEL = Material()
SIZE = 0.01  # [m]


def _jittered_box(n: int, curved: bool, seed: int = 0) -> tuple[StructuredTetMesh, np.ndarray]:
    """n^3-cell cube of side SIZE with interior corners moved by up to 20 % of a cell and,
    if ``curved``, every mid-edge node (boundary ones too) moved by up to 4 % of a cell
    off its edge. Returns the mesh and a mask of the nodes on the cube's surface."""
    rng = np.random.default_rng(seed)
    mesh = box_tet_mesh(SIZE, SIZE, SIZE, n, n, n)
    nodes = mesh.nodes.copy()
    # picks the cube's surface nodes: far above round-off, far below a cell
    boundary = (np.isclose(nodes, 0.0, atol=1e-12) | np.isclose(nodes, SIZE, atol=1e-12)).any(axis=1)
    cell = SIZE / n
    corners = np.unique(mesh.tets[:, :4])
    interior_corners = corners[~boundary[corners]]
    nodes[interior_corners] += 0.2 * cell * rng.uniform(-1, 1, (interior_corners.size, 3))
    t = mesh.tets
    nodes[t[:, 4:]] = 0.5 * (nodes[t[:, EDGES[:, 0]]] + nodes[t[:, EDGES[:, 1]]])
    if curved:
        mids = np.unique(t[:, 4:])
        nodes[mids] += 0.04 * cell * rng.uniform(-1, 1, (mids.size, 3))
    jittered = StructuredTetMesh(nodes=nodes, tets=t)
    assert (element_volumes(nodes[t]) > 0).all()
    return jittered, boundary


def test_assembly_matches_plain_coo_sum():
    mesh, _ = _jittered_box(2, curved=True)
    K = assemble_stiffness(mesh, STEEL, chunk_size=7)  # several chunks, odd size
    Ke = element_stiffness(mesh.nodes[mesh.tets], STEEL)
    dofs = element_dofs(mesh.tets)
    n = 3 * len(mesh.nodes)
    reference = sp.coo_matrix((Ke.ravel(), (np.repeat(dofs, 30, axis=1).ravel(), np.tile(dofs, (1, 30)).ravel())), shape=(n, n))
    difference = abs(K - reference.tocsr()).max()
    assert difference <= 1e-14 * abs(K).max()  # same sums, different order: round-off
    assert K.has_sorted_indices


@pytest.mark.parametrize("curved", [False, True])
def test_stiffness_symmetric_with_exactly_six_zero_modes(curved):
    mesh, _ = _jittered_box(2, curved=curved)
    K = assemble_stiffness(mesh, STEEL)
    scale = abs(K).max()
    assert abs(K - K.T).max() <= 1e-14 * scale  # element matrices symmetric up to round-off
    eigenvalues = np.linalg.eigvalsh(K.toarray())
    top = eigenvalues[-1]
    # Zero modes sit at round-off, eps * lambda_max * O(n) ~ 1e-13 lambda_max; the lowest
    # elastic mode of a compact cube is ~1e-3 lambda_max (measured). The thresholds split
    # that gap by three decades on each side.
    assert np.all(np.abs(eigenvalues[:6]) < 1e-10 * top)
    assert eigenvalues[6] > 1e-6 * top  # splits the gap (comment above)
    modes = rigid_body_modes(mesh.nodes)
    modes /= np.linalg.norm(modes, axis=0)
    assert np.abs(K @ modes).max() < 1e-12 * scale  # round-off of K r over rows of <= ~80 terms


def _patch_solve(mesh, boundary, K, u_exact, f=None):
    dofs = (3 * np.flatnonzero(boundary)[:, None] + np.arange(3)).ravel()
    f = np.zeros(K.shape[0]) if f is None else f
    K_ff, rhs, free = eliminate_dofs(K, f, dofs, u_exact.ravel()[dofs])
    u = np.empty(K.shape[0])
    u[free] = solve_spd(K_ff, rhs, method="splu")
    u[dofs] = u_exact.ravel()[dofs]
    return u.reshape(-1, 3)


@pytest.mark.parametrize("curved", [False, True])
def test_constant_strain_patch_test(curved):
    """A linear displacement prescribed on the boundary is reproduced exactly inside,
    with constant stress, on distorted straight and curved (isoparametric) tets."""
    mesh, boundary = _jittered_box(3, curved=curved, seed=1)
    assert affine_elements(mesh.nodes[mesh.tets]).all() != curved
    rng = np.random.default_rng(2)
    gradient = 1e-3 * rng.standard_normal((3, 3))  # strain ~ 1e-3
    u_exact = 1e-6 * rng.standard_normal(3) + mesh.nodes @ gradient.T
    K = assemble_stiffness(mesh, STEEL)
    u = _patch_solve(mesh, boundary, K, u_exact)
    # cond(K_ff) ~ 1e4 here: round-off 1e-12 of |u|; 1e-10 leaves margin and still
    # fails for any real inconsistency (a wrong element gives 1e-3 or worse)
    np.testing.assert_allclose(u[~boundary], u_exact[~boundary], atol=1e-10 * np.abs(u_exact).max())
    strain = 0.5 * (gradient + gradient.T)
    voigt = np.array([strain[0, 0], strain[1, 1], strain[2, 2], 2 * strain[1, 2], 2 * strain[0, 2], 2 * strain[0, 1]])
    stress = nodal_stress(mesh, STEEL, u)
    expected = elasticity_matrix(STEEL) @ voigt
    # gradient of u (round-off bound 1e-12 of |u|, above) over cells of 1/3 the cube: ~3e-12;
    # measured 6e-15 (was 1e-8)
    np.testing.assert_allclose(stress, np.broadcast_to(expected, stress.shape), atol=1e-11 * np.abs(expected).max())


def test_quadratic_field_is_exact_with_its_body_force():
    """P2 represents a quadratic displacement exactly: with the body force
    b = -div sigma (constant) and exact boundary values the interior is exact."""
    mesh, boundary = _jittered_box(2, curved=False, seed=3)
    rng = np.random.default_rng(4)
    Q = rng.standard_normal((3, 3, 3))
    Q = 0.5 * (Q + Q.transpose(0, 2, 1)) * 1e-2  # u_i = Q_ijk x_j x_k [m], x ~ 1e-2 m
    lam, mu = lame_parameters(STEEL)
    # -div sigma = -[(lam + mu) grad(div u) + mu laplacian u], with
    # d_i div u = 2 sum_m Q_mmi and laplacian u_i = 2 sum_j Q_ijj
    body = -((lam + mu) * 2 * np.einsum("mmi->i", Q) + mu * 2 * np.einsum("ijj->i", Q))
    u_exact = np.einsum("ijk,nj,nk->ni", Q, mesh.nodes, mesh.nodes)
    K = assemble_stiffness(mesh, STEEL)
    f = assemble_body_force(mesh, body)
    u = _patch_solve(mesh, boundary, K, u_exact, f)
    # a quadratic field is in the P2 space: round-off only, as in the linear patch test
    np.testing.assert_allclose(u[~boundary], u_exact[~boundary], atol=1e-10 * np.abs(u_exact).max())


def test_body_force_total_is_weight():
    mesh, _ = _jittered_box(2, curved=True, seed=5)
    gravity = np.array([0.0, 0.0, -9.81]) * STEEL.density
    f = assemble_body_force(mesh, gravity).reshape(-1, 3)
    volume = element_volumes(mesh.nodes[mesh.tets]).sum()
    # the quadrature weights sum to the volume: round-off only
    np.testing.assert_allclose(f.sum(axis=0), gravity * volume, rtol=1e-12)
    with pytest.raises(ValueError, match=r"\(3,\)"):
        assemble_body_force(mesh, [1.0, 2.0])


def test_check_mesh_rejects_bad_meshes():
    mesh = box_tet_mesh(1.0, 1.0, 1.0, 1, 1, 1)
    extra = StructuredTetMesh(nodes=np.vstack([mesh.nodes, [[5.0, 5.0, 5.0]]]), tets=mesh.tets)
    with pytest.raises(ValueError, match="belong to no tet"):
        check_mesh(extra)
    bad = StructuredTetMesh(nodes=mesh.nodes, tets=mesh.tets + 1000)
    with pytest.raises(ValueError, match="outside"):
        check_mesh(bad)

    class Linear:
        nodes = mesh.nodes
        tets = mesh.tets[:, :4]

    with pytest.raises(ValueError, match=r"\(n_tets, 10\)"):
        check_mesh(Linear())


def test_curved_patch_test_needs_the_higher_rule():
    """The 4-point rule is exact only on straight tets: on curved ones it fails the patch
    test (measured 7e-5), which is why curved tets get the 14-point rule."""
    from flexcal.fem.elements import TET_4POINT

    mesh, boundary = _jittered_box(3, curved=True, seed=1)
    rng = np.random.default_rng(2)
    u_exact = 1e-6 * rng.standard_normal(3) + mesh.nodes @ (1e-3 * rng.standard_normal((3, 3))).T
    u = _patch_solve(mesh, boundary, assemble_stiffness(mesh, STEEL, rule=TET_4POINT), u_exact)
    # measured 7e-5 (docstring): 70x this threshold, far above round-off
    assert np.abs(u - u_exact)[~boundary].max() > 1e-6 * np.abs(u_exact).max()


def test_inverted_tet_is_named_by_its_global_index():
    from flexcal.fem.elements import InvalidElementError

    mesh = box_tet_mesh(1.0, 1.0, 1.0, 2, 2, 2)
    tets = mesh.tets.copy()
    tets[37, [1, 2]] = tets[37, [2, 1]]  # swap two corners (and their mid-edge nodes)
    tets[37, 4:] = mesh.tets[37, [6, 5, 4, 7, 9, 8]]
    with pytest.raises(InvalidElementError, match="tet 37") as caught:
        assemble_stiffness(StructuredTetMesh(nodes=mesh.nodes, tets=tets), STEEL, chunk_size=10)
    np.testing.assert_array_equal(caught.value.elements, [37])
