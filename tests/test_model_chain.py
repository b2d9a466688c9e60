"""Eq. 1 chain compliance (model/chain.py): splitting, frame invariance, SPD, rigid modes."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from flexcal.geometry.frames import twist_transform
from flexcal.geometry.params import STEEL, reference_mechanism
from flexcal.model import chain, hinge


def relative_error(a, b):
    """Entry-wise relative error on the structurally non-zero entries (they span 10 decades)."""
    mask = np.abs(b) > 0
    return np.max(np.abs(a[mask] - b[mask]) / np.abs(b[mask]))


@pytest.mark.parametrize("pieces", [2, 3, 7])
def test_cantilever_split_into_pieces_reproduces_one_piece(pieces):
    length, height, width = 0.3, 0.02, 0.05
    whole = hinge.beam_compliance(length, height, width, STEEL)
    piece = hinge.beam_compliance(length / pieces, height, width, STEEL)
    ends = np.zeros((pieces, 3))
    ends[:, 0] = np.arange(1, pieces + 1) * length / pieces
    split = chain.serial_compliance(np.broadcast_to(piece, (pieces, 6, 6)), np.broadcast_to(np.eye(3), (pieces, 3, 3)),
                                    ends, np.array([length, 0.0, 0.0]))
    assert np.all(np.abs(split[np.abs(whole) == 0]) < 1e-30)  # the zero pattern is kept exactly
    assert relative_error(split, whole) < 1e-14  # beam theory is exact under splitting: rounding only


def test_sign_of_the_offset_matters():
    # REFERENCES.md pitfall: r = p_out - p_i flips the coupling blocks
    c = hinge.beam_compliance(0.1, 0.01, 0.02, STEEL)
    right = chain.serial_compliance(c[None], np.eye(3)[None], np.array([[0.1, 0, 0]]), np.array([0.3, 0, 0]))
    t_wrong = twist_transform(np.eye(3), np.array([0.2, 0, 0]))
    wrong = t_wrong @ c @ t_wrong.T
    assert wrong[1, 5] < c[1, 5] < right[1, 5]  # an output further from the clamp couples more
    # closed form: beam of length l clamped at 0, rigid arm to x = 0.3: C_uy,Mz = l^2/(2EI) + 0.2 l/(EI)
    ei = STEEL.youngs_modulus * 0.02 * 0.01**3 / 12
    # the same closed form: round-off only
    assert right[1, 5] == pytest.approx(0.1**2 / (2 * ei) + 0.2 * 0.1 / ei, rel=1e-13)


def test_fast_chain_compliance_equals_generic_eq1():
    for placement in reference_mechanism().chains:
        ch = placement.chain
        fast = chain.chain_compliance_matrix(ch, STEEL)
        generic = chain.serial_compliance(*chain.chain_elements(
            ch.length, ch.hinge_length, ch.width, ch.fillet, ch.thickness_1, ch.thickness_2, section=ch.section,
            connector_length=ch.connector_length, end_block_length=ch.end_block_length, material=STEEL),
            np.array([ch.length, 0.0, 0.0]))
        assert relative_error(fast, generic) < 1e-13  # same algebra, different association of the sums


def test_chain_compliance_is_frame_invariant():
    ch = reference_mechanism().chains[0].chain
    c_el, r_el, p_el = chain.chain_elements(ch.length, ch.hinge_length, ch.width, ch.fillet, ch.thickness_1,
                                            ch.thickness_2, section=ch.section, connector_length=ch.connector_length,
                                            end_block_length=ch.end_block_length, material=STEEL)
    local = chain.serial_compliance(c_el, r_el, p_el, np.array([ch.length, 0, 0]))
    rotation = Rotation.from_euler("zyx", [0.3, -1.1, 2.0]).as_matrix()
    offset = np.array([0.4, -0.2, 0.7])
    moved = chain.serial_compliance(c_el, rotation @ r_el, p_el @ rotation.T + offset,
                                    rotation @ np.array([ch.length, 0, 0]) + offset)
    back = twist_transform(rotation, np.zeros(3))  # chain-frame twist at B -> global twist at B
    assert relative_error(back.T @ moved @ back, local) < 1e-11  # relative to each entry; rounding of R
    # rounding of R, as above, against the largest entry
    np.testing.assert_allclose(back.T @ moved @ back, local, rtol=0, atol=1e-13 * np.abs(local).max())


def test_reference_chains_are_spd_with_and_without_actuator():
    mech = reference_mechanism()
    for placement in mech.chains:
        for actuator in (None, mech.actuator_stiffness):
            c = chain.chain_compliance_matrix(placement.chain, STEEL, actuator)
            # T C T^T sums are symmetric by construction: round-off only
            assert np.allclose(c, c.T, rtol=0, atol=1e-16 * np.abs(c).max())
            assert np.all(np.linalg.eigvalsh(c) > 0)
            k = chain.invert_axial_compliance(c)
            np.testing.assert_allclose(k @ c, np.eye(6), atol=1e-9)  # cond(C) ~ 1e6: 1e-9 is rounding
            assert np.all(np.linalg.eigvalsh(k) > 0)
    with_actuator = chain.chain_compliance_matrix(mech.chains[3].chain, STEEL, mech.actuator_stiffness)
    without = chain.chain_compliance_matrix(mech.chains[3].chain, STEEL)
    # the actuator adds 1/k in series: round-off only
    assert with_actuator[0, 0] - without[0, 0] == pytest.approx(1 / mech.actuator_stiffness, rel=1e-12)


def test_strut_is_not_rigid():
    # the brief's reason for modelling blocks and strut: a 327 mm x 50 mm strut's axial
    # compliance is of the order of the leaves'
    ch = reference_mechanism().chains[0].chain
    leaf = hinge.leaf_compliance(ch.hinge_length, ch.thickness_1, ch.width, ch.fillet, STEEL)[0, 0]
    strut = hinge.beam_compliance(ch.strut_length, ch.section, ch.section, STEEL)[0, 0]
    assert 0.1 < strut / leaf < 10  # 'of the order of': within a decade


def test_chain_stiffness_has_the_six_rigid_body_modes():
    ch = reference_mechanism().chains[3].chain
    k = chain.chain_stiffness_matrix(ch, STEEL)
    # round-off of inverting C (cond ~1e6, as above): ~1e-10
    assert np.allclose(k, k.T, rtol=0, atol=1e-9 * np.abs(k).max())
    w = twist_transform(np.eye(3), np.array([-ch.length, 0.0, 0.0]))
    modes = np.vstack([np.eye(6), w])  # A moves by a twist, B with it rigidly
    residual = k @ modes
    assert np.max(np.abs(residual)) < 1e-9 * np.abs(k).max()  # rounding of entries up to 1e9 N/m
    eig = np.linalg.eigvalsh(k)
    assert np.sum(eig > 1e-9 * eig.max()) == 6  # exactly six elastic modes


@settings(max_examples=25, deadline=None)
@given(t1=st.floats(2e-3, 5e-3), t2=st.floats(2e-3, 5e-3), a=st.floats(0, 8e-3), length=st.floats(0.13, 0.6))
def test_batched_chain_compliance_equals_looped_and_is_spd(t1, t2, a, length):
    lengths = np.array([length, length * 1.1])
    batch = chain.chain_compliance(lengths, 0.02, 0.04, a, np.array([t1, t2]), np.array([t2, t1]), section=0.05,
                                   connector_length=0.01, end_block_length=0.01, material=STEEL)
    for i in range(2):
        single = chain.chain_compliance(lengths[i], 0.02, 0.04, a, [t1, t2][i], [t2, t1][i], section=0.05,
                                        connector_length=0.01, end_block_length=0.01, material=STEEL)
        assert relative_error(batch[i], single) < 1e-12  # node count may differ between batch and single
        assert np.all(np.linalg.eigvalsh(single) > 0)


def test_compiled_chain_entries_equal_the_numpy_ones(monkeypatch):
    pytest.importorskip("numba")
    from flexcal.model import kernel

    rng = np.random.default_rng(4)
    shape = (60, 6)  # 360 chains >= COMPILED_MIN_CHAINS: the compiled kernel
    args = (rng.uniform(0.14, 0.5, shape), rng.uniform(18e-3, 22e-3, shape), rng.uniform(36e-3, 44e-3, shape),
            rng.uniform(0.0, 6.6e-3, shape), rng.uniform(2.7e-3, 4.4e-3, shape), rng.uniform(2.7e-3, 4.4e-3, shape))
    options = dict(section=np.full(6, 0.05), connector_length=np.full(6, 0.01), end_block_length=np.full(6, 0.01),
                   material=STEEL, actuator_stiffness=np.array([np.inf] * 3 + [2e8] * 3))
    compiled = chain.chain_compliance_entries(*args, **options)
    monkeypatch.setattr(kernel, "available", lambda: False)
    plain = chain.chain_compliance_entries(*args, **options)
    for key in plain:
        np.testing.assert_allclose(compiled[key], plain[key], rtol=1e-14, atol=0)  # same formulas, other order


def test_eq1_is_written_once():
    """Issue #25: one implementation of Eq. 1. The chain kernel compiles ``model.serial``'s own
    entry functions (no copy of the formulas), and ``chain`` re-exports its ``serial_compliance``."""
    pytest.importorskip("numba")
    from flexcal.model import _numba_kernels, serial

    assert _numba_kernels._moved_along_axis.py_func is serial.moved_along_axis
    assert _numba_kernels._quarter_turn.py_func is serial.quarter_turn
    assert chain.serial_compliance is serial.serial_compliance
    # the entry form is the 6x6 form: one element moved and turned, against the adjoint
    c = hinge.leaf_compliance(0.02, 0.004, 0.04, 0.005, STEEL)
    entries = np.array([c[i, j] for i, j in hinge.ENTRY_INDEX.values()])
    turned = serial.serial_compliance(c[None], chain.LEAF2_ROTATION[None], np.array([[0.1, 0, 0]]),
                                      np.array([0.35, 0, 0]))
    got = serial.serial_entries_along_axis(np.array(serial.quarter_turn(entries))[None], np.array([0.1]), 0.35)
    want = np.array([turned[i, j] for i, j in hinge.ENTRY_INDEX.values()])
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=0)  # same algebra, rounding only


def test_one_compiled_pass_gives_the_entries_and_the_elements(monkeypatch):
    """``chain_entries_and_elements`` (the consistent model's set-up, compiled at every batch
    size): its entries are ``chain_compliance_entries``' and its elements those
    ``shortening._element_entries`` lays out, both from the numpy formulas to rounding, on a
    batch of 12 chains (below COMPILED_MIN_CHAINS: numpy there)."""
    pytest.importorskip("numba")
    from flexcal.model import kernel, shortening

    rng = np.random.default_rng(5)
    shape = (2, 6)
    args = (rng.uniform(0.14, 0.5, shape), rng.uniform(18e-3, 22e-3, shape), rng.uniform(36e-3, 44e-3, shape),
            rng.uniform(0.0, 6.6e-3, shape), rng.uniform(2.7e-3, 4.4e-3, shape), rng.uniform(2.7e-3, 4.4e-3, shape))
    options = dict(section=np.full(6, 0.05), connector_length=np.full(6, 0.01), end_block_length=np.full(6, 0.01),
                   material=STEEL)
    entries, elements, offsets = chain.chain_entries_and_elements(*args, **options)
    assert elements.shape == shape + (9, 8) and offsets.shape == shape + (9,)
    monkeypatch.setattr(kernel, "available", lambda: False)
    plain = chain.chain_compliance_entries(*args, **options)
    plain_elements, plain_offsets = shortening._element_entries(*args, **options)
    for key in plain:
        np.testing.assert_allclose(entries[key], plain[key], rtol=1e-14, atol=0)  # same formulas, other order
    # each element's entries of its own size: the same formulas, one at a time against batched
    np.testing.assert_allclose(elements, plain_elements, rtol=1e-14, atol=0)
    np.testing.assert_allclose(offsets, plain_offsets, rtol=0, atol=1e-15)  # [m] the same sums of lengths
