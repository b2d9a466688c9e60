"""A chain joined through section fields as one stiffness on its segments' twists
(flexcal.fem.cut_warping; docs/meshing.md, "Session 24: the tied-cut frame")."""

import functools

import numpy as np
import pytest

from flexcal.fem.cut_warping import (clamped_end_stiffness, rigid_field_coefficients, rigid_part_stiffness,
                                     section_gram_diagonal, warping_basis)
from flexcal.fem.interface import RIGID, section_modes
from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS
from flexcal.validation.prototype.segments import section_nodes
from flexcal.validation.reports.chain_cuts import (chain_order_matrices, cut_orders, interface_condensed,
                                                   interface_scale, interface_segments, joined_through_interface,
                                                   twist_stiffness_through_interface)
from flexcal.validation.reports.chain_reference import reference_chain

# the coarse whole L1 chain (2 through), d2 at the mid-connector cuts and p2 at the strut cuts
INTERFACE = ("d2", "p2", "p2", "d2")


@functools.cache
def _coarse_chain(interface):
    chain = reference_chain("L1")
    plan = interface_segments(chain, 5)
    scale = interface_scale(chain, 5)
    condensed = interface_condensed(plan, interface, 2, {**PROTOTYPE_CHAIN_OPTIONS, "slenderness": None},
                                    scale=scale)
    return chain, plan, condensed, scale


@pytest.mark.parametrize("order", [1, 2, 5, 12])
def test_a_field_splits_into_its_least_squares_rigid_motion_and_a_warping(order):
    scale = 0.025
    rigid, warping = rigid_field_coefficients(order, scale), warping_basis(order, scale)
    points = np.column_stack([np.zeros(7), np.linspace(-scale, scale, 7), np.linspace(scale, -0.3 * scale, 7)])
    field = section_modes(points, np.zeros(3), order, scale).reshape(21, -1)
    # E reproduces the rigid motions pointwise (a least-squares fit of polynomials that hold
    # them exactly: round-off of a Legendre Vandermonde solve, measured <= 1e-15 m); 1e-12
    assert np.abs(field @ rigid - section_modes(points, np.zeros(3), RIGID, scale).reshape(21, 6)).max() <= 1e-12
    basis = np.hstack([rigid, warping])
    assert basis.shape == (rigid.shape[0],) * 2 and np.linalg.matrix_rank(basis) == rigid.shape[0]
    # the warping carries no rigid motion in the face's L2 sense: round-off of null_space, ~1e-16; 1e-12
    assert np.abs(warping.T @ (section_gram_diagonal(order)[:, None] * rigid)).max() <= 1e-12


def test_rigid_ties_give_the_segments_end_blocks_on_the_diagonal_exactly():
    chain, plan, condensed, scale = _coarse_chain("rigid")
    K_chain = twist_stiffness_through_interface(plan, condensed, "rigid", scale)
    blocks = [k[6:, 6:] for k in chain_order_matrices(plan, condensed, "rigid")]
    expected = np.zeros((30, 30))
    for s, block in enumerate(blocks):
        expected[6 * s:6 * s + 6, 6 * s:6 * s + 6] = block
    np.testing.assert_array_equal(K_chain, expected)  # no warping: nothing is condensed


@pytest.mark.parametrize("interface", [INTERFACE, "rigid"])
def test_the_twist_stiffness_with_its_bodies_condensed_is_the_tied_chains_end_block(interface):
    chain, plan, condensed, scale = _coarse_chain(interface)
    K_chain = twist_stiffness_through_interface(plan, condensed, interface, scale)
    end_block = clamped_end_stiffness(K_chain, np.diff(section_nodes(chain)))
    joined = joined_through_interface(plan, condensed, interface)[6:, 6:]
    size = np.sqrt(np.outer(np.diag(joined), np.diag(joined)))
    # the same energy minimised in two orders. The transverse translations' stiffness at B is the
    # small difference of rotation stiffnesses times lever arms (Ad(D)), so it carries the
    # round-off of that cancellation: measured <= 1.8e-8 of the diagonals' geometric mean with
    # the fields, 7.3e-9 with rigid ties (where K_chain is blockdiag(K_jj) to the bit), 2.5e-12
    # on the axial entry; the fields move the entries by > 1e-2 (below); 1e-6
    assert np.all(np.abs(end_block - joined) <= 1e-6 * size), np.max(np.abs(end_block - joined) / size)
    if interface != "rigid":  # the fields make the chain softer than rigid ties, so the check has teeth
        # (measured: by far more than the 1e-6 above on the coarse chain); 1e-2
        rigid = joined_through_interface(*_coarse_chain("rigid")[1:3], "rigid")[6:, 6:]
        assert np.max(np.abs(rigid - joined) / size) > 1e-2  # 1e-2: the fields soften 0.37 on K[ux,ux] here


def test_the_twist_stiffness_is_symmetric_positive_definite_and_couples_the_segments():
    chain, plan, condensed, scale = _coarse_chain(INTERFACE)
    K_chain = twist_stiffness_through_interface(plan, condensed, INTERFACE, scale)
    np.testing.assert_array_equal(K_chain, K_chain.T)
    # positive definite with margin, measured on the Jacobi-scaled matrix (D^-1/2 K D^-1/2, D its
    # diagonal: the entries span axial strut ~1e9 N/m to leaf shear): smallest eigenvalue 0.0107
    # (rigid ties: 0.0097), against a round-off floor ~30 x 1e-16; 1e-3
    root = 1.0 / np.sqrt(np.diag(K_chain))
    eigenvalues = np.linalg.eigvalsh(K_chain * root[:, None] * root[None, :])
    assert eigenvalues[0] > 1e-3, eigenvalues[[0, -1]]  # 1e-3: see above
    units = np.tile(np.r_[np.ones(3), np.full(3, 1 / scale)], 5)  # rotations as displacements at the 25 mm rim
    scaled = K_chain / units[:, None] / units[None, :]
    # the warping couples neighbouring segments: off-diagonal blocks are not small (measured
    # 0.024 of the diagonal block; rigid ties give exactly 0 there); 1e-3
    coupling = np.abs(scaled[0:6, 6:12]).max() / np.abs(scaled[0:6, 0:6]).max()
    assert coupling > 1e-3, coupling  # 1e-3: rigid ties give exactly 0


def test_the_rigid_part_of_rigid_ties_is_the_segments_matrix_and_of_kinematic_fields_the_rigidly_tied_one():
    _, plan, rigid_condensed, scale = _coarse_chain("rigid")
    rigid = chain_order_matrices(plan, rigid_condensed, "rigid")
    # E = I at rigid ties: the matrices themselves (products with 0 and 1 are exact)
    np.testing.assert_array_equal(rigid_part_stiffness(rigid, cut_orders(plan, "rigid"), scale), np.array(rigid))
    _, plan, condensed, scale = _coarse_chain(INTERFACE)
    parts = rigid_part_stiffness(chain_order_matrices(plan, condensed, INTERFACE), cut_orders(plan, INTERFACE), scale)
    size = np.sqrt(np.outer(np.diag(rigid[2]), np.diag(rigid[2])))
    # the strut [s0, s1] between two kinematic p2 fields, on the same mesh as its rigid ties: a field
    # held to q = E r moves the face rigidly (E exact, above), so this is the rigid tie's condensation
    # up to the round-off of two different solves (K_ii's factorisations differ: the p2 faces' nodes are
    # slaves of other masters); measured 7e-14 of the diagonals' geometric mean; 1e-9
    assert np.all(np.abs(parts[2] - rigid[2]) <= 1e-9 * size), np.max(np.abs(parts[2] - rigid[2]) / size)
    # a distributing field held rigid holds only the face's L2 projection: softer than the rigid tie
    # (measured: the [0, m1] segment's end block loses 0.15 on K[ux,ux]); 1e-3
    end = np.diag(parts[0])[6:] / np.diag(rigid[0])[6:]
    assert end[0] < 1 - 1e-3, end  # 1e-3: far below what the field frees, far above round-off


def test_condensing_the_warping_only_softens_the_rigid_parts_frame():
    _, plan, condensed, scale = _coarse_chain(INTERFACE)
    matrices, orders = chain_order_matrices(plan, condensed, INTERFACE), cut_orders(plan, INTERFACE)
    K_chain = twist_stiffness_through_interface(plan, condensed, INTERFACE, scale)
    held = np.zeros((30, 30))  # the warping held at zero: each segment's rigid part's end block
    for s, part in enumerate(rigid_part_stiffness(matrices, orders, scale)):
        held[6 * s:6 * s + 6, 6 * s:6 * s + 6] = part[6:, 6:]
    root = 1.0 / np.sqrt(np.diag(held))
    eigenvalues = np.linalg.eigvalsh((held - K_chain) * root[:, None] * root[None, :])
    # K_chain is the minimum over the warping, held its value at w = 0, so held - K_chain is positive
    # semi-definite: its Jacobi-scaled eigenvalues >= -round-off (measured +8e-18); -1e-10
    assert eigenvalues[0] >= -1e-10, eigenvalues[0]
    assert eigenvalues[-1] > 1e-2, eigenvalues[-1]  # 1e-2: the warping frees a lot (measured 0.23), not nothing
