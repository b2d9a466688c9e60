"""The faster assembly and condensation of the cold truth (issue 26, docs/scale.md) give
the same bits as the code they replaced: the node pattern of ``np.unique``, the nine
strided ``np.add.at`` of the assembly, the sparse product T^T K T with its slices and
``sp.triu``, and PARDISO's factorize-then-solve. The references below are the replaced
code, kept here verbatim in substance; every comparison is exact (``np.array_equal``)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from flexcal.fem.assembly import assemble_stiffness, check_mesh, node_pattern
from flexcal.fem.condense import condensation_blocks, reduced_system, solve_chain
from flexcal.fem.coupling import RigidCoupling, select_plane_nodes
from flexcal.fem.elements import EDGES, element_stiffness_blocks
from flexcal.fem.mesh_mapped_chain import FAST_CHAIN_OPTIONS, mapped_mesh_chain
from flexcal.fem.solve import _pardiso_solver, pardiso_available, solve_spd
from flexcal.fem.structured import StructuredTetMesh, box_tet_mesh
from flexcal.geometry.exact import end_planes, reference_points
from flexcal.geometry.params import STEEL, ChainSegment, reference_mechanism
from flexcal.validation.prototype.segments import section_nodes

D1 = reference_mechanism().chains[3].chain
# block, leaf 1 and half the connector, at 2 cells through the neck: curved P2 elements
# on the fillets, straight ones elsewhere, both quadrature rules (as the prototype's segments)
SEGMENT = ChainSegment(chain=D1, x_start=0.0, x_end=float(section_nodes(D1)[1]))


def _reference_pattern(tets: np.ndarray, n_nodes: int):
    keys = (tets[:, :, None] * n_nodes + tets[:, None, :]).ravel()
    unique, slot = np.unique(keys, return_inverse=True)
    rows = unique // n_nodes
    indices = unique - rows * n_nodes
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n_nodes))])
    return indptr, indices, slot.reshape(len(tets), 10, 10)


def _reference_assembly(mesh, chunk_size: int = 256) -> sp.csr_matrix:
    nodes, tets = check_mesh(mesh)
    indptr, indices, slot = _reference_pattern(tets, len(nodes))
    accumulator = np.zeros((3, 3, indices.size))
    for start in range(0, len(tets), chunk_size):
        chunk = slice(start, start + chunk_size)
        Ke = element_stiffness_blocks(nodes[tets[chunk]], STEEL)
        where = slot[chunk].ravel()
        for i in range(3):
            for j in range(3):
                np.add.at(accumulator[i, j], where, Ke[:, i, :, j, :].ravel())
    blocks = np.ascontiguousarray(accumulator.transpose(2, 0, 1))
    K = sp.bsr_matrix((blocks, indices, indptr), shape=(3 * len(nodes),) * 2).tocsr()
    K.sort_indices()
    return K


def _curved_box() -> StructuredTetMesh:
    """A 4^3-cell cube with every mid-edge node moved off its edge (all tets curved)."""
    rng = np.random.default_rng(3)
    mesh = box_tet_mesh(0.01, 0.01, 0.01, 4, 4, 4)
    nodes = mesh.nodes.copy()
    mids = np.unique(mesh.tets[:, 4:])
    nodes[mids] += 0.04 * 0.0025 * rng.uniform(-1, 1, (mids.size, 3))
    return StructuredTetMesh(nodes=nodes, tets=mesh.tets)


@pytest.fixture(scope="module")
def segment_mesh():
    mesh, _ = mapped_mesh_chain(SEGMENT, elements_through_thickness=2, measure=False, quality=False,
                                **FAST_CHAIN_OPTIONS)
    return mesh


def _same_csr(a: sp.csr_matrix, b: sp.csr_matrix) -> bool:
    return (a.shape == b.shape and np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
            and np.array_equal(a.data, b.data))


def test_node_pattern_is_np_unique_s(segment_mesh):
    nodes, tets = check_mesh(segment_mesh)
    for got, want in zip(node_pattern(tets, len(nodes)), _reference_pattern(tets, len(nodes))):
        assert got.dtype == want.dtype and np.array_equal(got, want)


def test_assembly_gives_the_replaced_code_s_bits(segment_mesh):
    assert _same_csr(assemble_stiffness(segment_mesh, STEEL), _reference_assembly(segment_mesh))
    curved = _curved_box()
    assert _same_csr(assemble_stiffness(curved, STEEL), _reference_assembly(curved))
    # the chunk size does not change a sum: each entry adds its elements in element order
    assert _same_csr(assemble_stiffness(curved, STEEL, chunk_size=7), _reference_assembly(curved))
    assert np.count_nonzero(np.abs(curved.nodes[curved.tets[:, 4:]] - 0.5 * (
        curved.nodes[curved.tets[:, EDGES[:, 0]]] + curved.nodes[curved.tets[:, EDGES[:, 1]]])) > 0) > 0


def _couplings(mesh, segment):
    planes, points = end_planes(segment), reference_points(segment)
    return [RigidCoupling(nodes=select_plane_nodes(mesh, planes[end]), reference_point=points[end]) for end in "AB"]


def test_condensation_blocks_are_those_of_the_sparse_product(segment_mesh):
    couplings = _couplings(segment_mesh, SEGMENT)
    K = assemble_stiffness(segment_mesh, STEEL)
    _, cmap, K_r = reduced_system(segment_mesh, STEEL, couplings, K)
    n_i = cmap.free_node_dofs.size
    upper, K_im, K_mm = condensation_blocks(K, cmap)
    want_upper = sp.triu(K_r[:n_i, :n_i].tocsr(), format="csr")
    want_upper.sort_indices()
    assert _same_csr(upper, want_upper)
    assert np.array_equal(K_im, K_r[:n_i, n_i:].toarray())
    assert np.array_equal(K_mm, K_r[n_i:, n_i:].toarray())
    # an entry that is exactly zero in K is dropped from the triangle as the product drops it
    zeroed = K.copy()
    zeroed.data[np.flatnonzero(zeroed.data)[::97]] = 0.0
    _, cmap, K_r = reduced_system(segment_mesh, STEEL, couplings, zeroed)
    want_upper = sp.triu(K_r[:n_i, :n_i].tocsr(), format="csr")
    want_upper.sort_indices()
    assert _same_csr(condensation_blocks(zeroed, cmap)[0], want_upper)


@pytest.mark.skipif(not pardiso_available(), reason="PARDISO (pypardiso + MKL) not available")
def test_chain_stiffness_has_the_bits_of_the_replaced_path(segment_mesh):
    """solve_chain on PARDISO (the upper triangle from K, one phase-13 call) against the
    replaced path: T^T K T sliced, sp.triu, factorize (phase 12) then solve (phase 33)."""
    planes, points = end_planes(SEGMENT), reference_points(SEGMENT)
    got = solve_chain(segment_mesh, STEEL, planes["A"], points["A"], planes["B"], points["B"], method="pardiso")
    _, cmap, K_r = reduced_system(segment_mesh, STEEL, _couplings(segment_mesh, SEGMENT))
    n_i = cmap.free_node_dofs.size
    K_im, K_mm = K_r[:n_i, n_i:].toarray(), K_r[n_i:, n_i:].toarray()
    upper = sp.triu(K_r[:n_i, :n_i].tocsr(), format="csr")
    upper.sort_indices()
    solver = _pardiso_solver()
    try:
        solver.factorize(upper)
        X = solver.solve(upper, np.asfortranarray(K_im))
    finally:
        solver.free_memory(everything=True)
    assert np.array_equal(got.stiffness, K_mm - K_im.T @ X)
    # the other solvers take the mirrored triangle: the same matrix to their round-off
    splu = solve_spd(upper, K_im, method="splu", upper_triangle=True)
    assert np.max(np.abs(splu - X)) <= 1e-9 * np.max(np.abs(X))  # two direct solvers on one SPD system


def test_upper_triangle_refuses_a_lower_entry():
    with pytest.raises(ValueError, match="below the diagonal"):
        solve_spd(sp.csr_matrix(np.array([[2.0, 0.0], [1.0, 2.0]])), np.ones(2), upper_triangle=True)
