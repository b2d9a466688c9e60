"""The chains' second-order forms (``model.shortening.chain_second_order_forms``: shortening S,
lateral defect L, load form T), batched and compiled on the elements' eight entries, against the
module docstring's mathematics evaluated chain by chain here in the plainest way (S and L: dense
adjoints, a matrix inverse, the twist bracket with cross products and the quadratic defect read
off by polarisation), and against the dense numpy route used without numba (S, L, T)."""

import numpy as np
import pytest

from flexcal.geometry.frames import twist_transform
from flexcal.geometry.params import reference_mechanism
from flexcal.model import kernel
from flexcal.model.chain import chain_elements
from flexcal.model.shortening import _dense_forms, chain_second_order_forms


def _bracket(a, b):
    """[a, b] of twists (v, w): (w_a x v_b - w_b x v_a, w_a x w_b)."""
    return np.r_[np.cross(a[3:], b[:3]) - np.cross(b[3:], a[:3]), np.cross(a[3:], b[3:])]


def _plain_forms(dims, section, connector, end_block, material):
    """(S (6, 6), L (5, 6, 6)) of one chain, written from the docstrings of ``model.shortening``."""
    length = dims[0]
    compliance, rotation, points = chain_elements(*dims, section=section, connector_length=connector,
                                                  end_block_length=end_block, material=material)
    moved = []
    for c_e, r_e, p_e in zip(compliance, rotation, points):
        t_e = twist_transform(r_e, p_e - np.array([length, 0.0, 0.0]))  # element end -> B
        moved.append(t_e @ c_e @ t_e.T)
    k_b = np.linalg.inv(sum(moved))
    gains = [c_e @ k_b for c_e in moved]  # eta_e = G_e D

    def defect(d):  # m(D) = (-1/2 phi x d, 0) - 1/2 sum_{e<f} [G_e D, G_f D]
        eta = [g @ d for g in gains]
        out = np.r_[-0.5 * np.cross(d[3:], d[:3]), np.zeros(3)]
        for f in range(len(eta)):
            for e in range(f):
                out -= 0.5 * _bracket(eta[e], eta[f])
        return out

    unit = np.eye(6)
    tensor = np.zeros((6, 6, 6))  # m_c(D) = D^T M[c] D, M symmetric: by polarisation
    for p in range(6):
        tensor[:, p, p] = defect(unit[p])
        for q in range(p):
            tensor[:, p, q] = tensor[:, q, p] = 0.5 * (defect(unit[p] + unit[q]) - defect(unit[p]) - defect(unit[q]))
    k = k_b[0, 0]
    form = k * tensor[0] + 2.0 * k_b.T @ tensor[:, 0, :]
    form = 0.5 * (form + form.T) / k
    form[0, :] = form[:, 0] = 0.0
    lateral = tensor[1:].copy()  # the defect's rows y..rz, the axial direction's rows and columns zero
    lateral[:, 0, :] = lateral[:, :, 0] = 0.0
    return form, lateral


@pytest.fixture(scope="module")
def chains():
    """4 x 6 chains of the reference mechanism, each dimension but the length off nominal by
    up to +-10 % (the parameter space's range), and their fixed sizes."""
    mech = reference_mechanism()
    nominal = [p.chain for p in mech.chains]
    dims = np.array([[c.length, c.hinge_length, c.width, c.fillet, c.thickness_1, c.thickness_2] for c in nominal])
    scale = np.where(np.arange(6) == 0, 1.0, np.random.default_rng(11).uniform(0.9, 1.1, (4, 6, 6)))
    fixed = [np.array([getattr(c, name) for c in nominal]) for name in ("section", "connector_length",
                                                                        "end_block_length")]
    return dims[None] * scale, fixed, mech.material


def _scaled(form, length):
    """S in consistent units: rows and columns of the rotations times the chain length [m], so
    that every entry is of the size of the translation entries [1/m]."""
    unit = np.r_[np.ones(3), np.full(3, length)]
    return form * unit[:, None] * unit[None, :]


@pytest.mark.skipif(not kernel.available(), reason="the compiled form needs numba")
def test_the_compiled_forms_are_the_docstrings_mathematics(chains):
    dims, (section, connector, end_block), material = chains
    fast, fast_lateral, _ = chain_second_order_forms(*np.moveaxis(dims, -1, 0), section=section,
                                                     connector_length=connector, end_block_length=end_block,
                                                     material=material)
    assert fast.shape == (4, 6, 6, 6) and fast_lateral.shape == (4, 6, 5, 6, 6)
    for cand, chain in np.ndindex(4, 6):
        plain, lateral = _plain_forms(dims[cand, chain], section[chain], connector[chain], end_block[chain],
                                      material)
        length = dims[cand, chain, 0]
        # L's components y, z [m] and rx, ry, rz [rad]: the rotations' rows times the length too
        component = np.r_[np.ones(2), np.full(3, length)][:, None, None]
        got, want = _scaled(fast[cand, chain], length), _scaled(plain, length)
        # 1e-13 of S's largest entry: the polarisation reads L off values of the whole defect
        # m(D), of S's size (L's entries are ~0.1 of it, its structural zeros come out ~1e-14)
        np.testing.assert_allclose(_scaled(fast_lateral[cand, chain], length) * component,
                                   _scaled(lateral, length) * component, rtol=0,
                                   atol=1e-13 * np.max(np.abs(want)))  # 1e-13 of S's largest entry (above)
        assert np.max(np.abs(_scaled(lateral, length) * component)) > 1e-3 * np.max(np.abs(want))  # L is there
        # 1e-13 of the largest entry: both sum the same ~1e2 terms in another order; the
        # polarisation here subtracts quadratic values (measured agreement 5e-15, fast vs
        # dense too); an omitted element or bracket term is >= 1e-3
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * np.max(np.abs(want)))
        assert np.max(np.abs(want)) > 0.1  # [1/m]: a real form (the pivot form's 1/(2 L_y) ~ 1)


@pytest.mark.skipif(not kernel.available(), reason="the compiled form needs numba")
def test_the_compiled_forms_equal_the_dense_ones(chains):
    """The dense route (``_transported_elements``, ``_defect``, ``_load_form``; used without
    numba) gives the same S, L and T."""
    dims, (section, connector, end_block), material = chains
    args = dict(section=section, connector_length=connector, end_block_length=end_block, material=material)
    fast = chain_second_order_forms(*np.moveaxis(dims, -1, 0), **args)
    dense = _dense_forms(*np.moveaxis(dims, -1, 0), **args)
    # of each chain's form's largest entry: the same sums in another order; measured 1e-14 (S),
    # 5e-14 (L) and 4e-12 (T: K (C1 K C1 - C2) K subtracts terms ~1e2 x T)
    for name, got, want, bound in zip("SLT", fast, dense, (1e-13, 1e-12, 1e-10)):
        scale = np.max(np.abs(want), axis=tuple(range(2, want.ndim)), keepdims=True)
        assert np.all(scale > 0), name
        excess = np.max(np.abs(got - want) / scale)
        assert excess <= bound, (name, excess)


def test_the_compiled_bracket_constants_are_the_twist_brackets_entries():
    """``_numba_shortening``'s compiled-in bracket entries are exactly the non-zero entries of
    ``twist_bracket_tensor`` (in its order), and PARTNER pairs the indices of the off-diagonal
    entries of ``hinge.ENTRY_INDEX`` (the 2x2 blocks of a collinear chain's matrices), -1 elsewhere."""
    from flexcal.model import _numba_shortening as fast
    from flexcal.model.hinge import ENTRY_INDEX
    from flexcal.model.shortening import twist_bracket_tensor

    bracket = twist_bracket_tensor()
    nonzero = np.nonzero(bracket)
    for constant, expected in zip((fast.BRACKET_C, fast.BRACKET_P, fast.BRACKET_R), nonzero):
        np.testing.assert_array_equal(constant, expected)
    np.testing.assert_array_equal(fast.BRACKET_VALUE, bracket[nonzero])
    partner = np.full(6, -1)
    for i, j in ENTRY_INDEX.values():
        if i != j:
            partner[i], partner[j] = j, i
    np.testing.assert_array_equal(fast.PARTNER, partner)
