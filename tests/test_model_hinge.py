"""Hinge compliance (model/hinge.py): every entry against quad over the real profile,
the published worked example, the corner-filleted composition, SPD, batching."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flexcal.geometry.frames import twist_transform
from flexcal.geometry.params import STEEL, CircularNotchHinge, LeafHinge, Material
from flexcal.model import hinge

from helpers import quad_hinge_entries


def quad_entries(flat_half, fillet, thickness, width, material=STEEL):
    """The Euler-Bernoulli/Timoshenko integrals of the module docstring, by adaptive quad."""
    half = flat_half + fillet

    def t(x):
        return float(hinge.profile_thickness(x, flat_half, fillet, thickness))

    breaks = sorted({-half, -flat_half, 0.0, flat_half, half})
    # the torsion formula switches long/short side where t(x) = width: split there too
    if fillet > 0 and thickness < width < thickness + 2 * fillet:
        u = np.sqrt(fillet**2 - (fillet - (width - thickness) / 2) ** 2)
        breaks = sorted(set(breaks) | {-(flat_half + u), flat_half + u})
    return quad_hinge_entries(t, half, breaks, width, material)


CASES = [  # (flat half-length c, fillet rho, thickness t, width w) [m]
    (4e-3, 6e-3, 4e-3, 40e-3),  # reference load-chain leaf (l 20, a 6, t 4, w 40 mm)
    (4e-3, 6e-3, 3e-3, 40e-3),  # reference driving-chain leaf
    (2.9e-3, 6.6e-3, 2.7e-3, 44e-3),  # driving leaf at the -10 % / +10 % corners
    (0.0, 5e-3, 1e-3, 10e-3),  # REFERENCES.md circular notch (t/R = 0.2, torsion split at t = w)
    (0.0, 5e-3, 0.1e-3, 10e-3),  # thin circular notch, t/R = 0.02
    (5e-3, 0.0, 4e-3, 40e-3),  # plain leaf (no fillet)
    (10e-3, 0.0, 50e-3, 50e-3),  # square block (Timoshenko beam)
    (1e-3, 8e-3, 1e-3, 5e-3),  # narrow leaf: t(x) crosses w inside the fillet
]


@pytest.mark.parametrize("case", CASES)
def test_every_entry_matches_quad_over_the_profile(case):
    got = hinge.segment_entries(*case, STEEL.youngs_modulus, STEEL.poisson_ratio)
    expected = quad_entries(*case)
    for key, value in expected.items():
        # 1e-11: quad is asked for 1e-13, the closed forms are exact and the Gauss-Legendre
        # node rule was fitted for 3e-14 (gauss_node_count); 1e-11 leaves room for both
        assert float(got[key]) == pytest.approx(value, rel=1e-11), key


def test_worked_example_of_the_circular_notch():
    # REFERENCES.md: R 5, t 1, b 10 mm, E 206 GPa -> 0.0149514 rad/(N m), quoted to 6 digits
    c = hinge.circular_notch_compliance(5e-3, 1e-3, 10e-3, Material(youngs_modulus=206e9))
    assert c[5, 5] == pytest.approx(0.0149514, abs=5e-8)  # half a unit in the last quoted digit
    closed = hinge.circular_notch_rotation_compliance(5e-3, 1e-3, 10e-3, 206e9)
    assert c[5, 5] == pytest.approx(float(closed), rel=1e-15)  # the same formula


def test_simplified_notch_formula_error_is_as_published():
    # REFERENCES.md: 9 pi sqrt(R)/(2 E b t^2.5) is 1.3 % high at t/R = 0.1 and 6.8 % at 0.5
    for ratio, excess in ((0.1, 0.013), (0.5, 0.068)):
        r, t, b = 5e-3, ratio * 5e-3, 10e-3
        exact = float(hinge.circular_notch_rotation_compliance(r, t, b, 206e9))
        simple = 9 * np.pi * np.sqrt(r) / (2 * 206e9 * b * t**2.5)
        assert simple / exact - 1 == pytest.approx(excess, abs=0.001)  # the quoted values have 2 digits


def test_corner_filleted_leaf_is_flat_part_plus_circular_notch():
    l, a, t, w = 20e-3, 6e-3, 4e-3, 40e-3
    c = hinge.leaf_compliance(l, t, w, a, STEEL)
    lobontiu = 12 * (l - 2 * a) / (STEEL.youngs_modulus * w * t**3) + hinge.circular_notch_rotation_compliance(
        a, t, w, STEEL.youngs_modulus)
    assert c[5, 5] == pytest.approx(float(lobontiu), rel=1e-14)  # same closed forms, rounding only


def test_compiled_and_numpy_quadrature_agree():
    pytest.importorskip("numba")
    rng = np.random.default_rng(0)
    r, t, w = rng.uniform(1e-3, 8e-3, 600), rng.uniform(0.2e-3, 5e-3, 600), rng.uniform(2e-3, 40e-3, 600)
    compiled = hinge._arc_quadrature(r, t, w)  # 600 arcs >= COMPILED_MIN_ARCS: numba
    plain = hinge._arc_quadrature_numpy(r, t, w)
    for key in plain:
        np.testing.assert_allclose(compiled[key], plain[key], rtol=1e-13)  # same nodes, summation order only


@pytest.mark.parametrize("make", [
    lambda: LeafHinge(length=20e-3, thickness=4e-3, width=40e-3, fillet=6e-3, block_length=10e-3),
    lambda: CircularNotchHinge(radius=5e-3, thickness=1e-3, width=10e-3, block_length=5e-3),
])
def test_hinge_matrix_is_spd_and_moved_to_the_free_face(make):
    h = make()
    c = hinge.hinge_compliance_matrix(h, STEEL)
    np.testing.assert_allclose(c, c.T, rtol=0, atol=1e-15 * np.abs(c).max())  # exactly symmetric up to rounding
    assert np.all(np.linalg.eigvalsh(c) > 0)
    notch = hinge.leaf_compliance(h.length, h.thickness, h.width, h.fillet, STEEL) if isinstance(h, LeafHinge) \
        else hinge.circular_notch_compliance(h.radius, h.thickness, h.width, STEEL)
    # rigid block of length b in front of the notch: C_rz,Mz unchanged, C_uy,Fy grows by 2 b C_uy,Mz + b^2 C_rz,Mz
    b = h.block_length
    assert c[5, 5] == pytest.approx(notch[5, 5], rel=1e-14)  # a rigid block leaves C_rz,Mz unchanged: round-off only
    # the closed form above: round-off only
    assert c[1, 1] == pytest.approx(notch[1, 1] + 2 * b * notch[1, 5] + b * b * notch[5, 5], rel=1e-13)
    t = twist_transform(np.eye(3), np.array([-b, 0, 0]))
    np.testing.assert_allclose(c, t @ notch @ t.T, rtol=1e-14, atol=0)  # as above


@pytest.mark.parametrize("shape", [(), (1,), (4,), (2, 3), (3, 1, 2)])
def test_batched_equals_looped(shape):
    rng = np.random.default_rng(sum(shape) + len(shape))
    size = int(np.prod(shape)) if shape else 1
    l = rng.uniform(15e-3, 25e-3, size).reshape(shape)
    a = rng.uniform(0, 7e-3, size).reshape(shape)
    t = rng.uniform(2e-3, 5e-3, size).reshape(shape)
    w = rng.uniform(30e-3, 45e-3, size).reshape(shape)
    batched = hinge.leaf_compliance(l, t, w, a, STEEL)
    assert batched.shape == shape + (6, 6)
    for index in np.ndindex(*shape):
        single = hinge.leaf_compliance(float(l[index]), float(t[index]), float(w[index]), float(a[index]), STEEL)
        # the node count follows the batch's worst arc, so a batch may use more nodes than one
        # hinge alone: both are converged to ~3e-14, hence 1e-12
        np.testing.assert_allclose(batched[index], single, rtol=1e-12, atol=0)


@settings(max_examples=40, deadline=None)
@given(l=st.floats(8e-3, 40e-3), a_frac=st.floats(0.0, 0.5), t=st.floats(0.3e-3, 6e-3), w=st.floats(3e-3, 60e-3))
def test_leaf_compliance_is_spd_and_softens_when_thinner(l, a_frac, t, w):
    a = a_frac * l
    c = hinge.leaf_compliance(l, t, w, a, STEEL)
    assert np.all(np.linalg.eigvalsh(c) > 0)
    thinner = hinge.leaf_compliance(l, 0.9 * t, w, a, STEEL)
    assert thinner[5, 5] > c[5, 5] and thinner[1, 1] > c[1, 1] and thinner[0, 0] > c[0, 0]
    # C_ry,My = (12 / w^2) C_ux,Fx holds for any profile (both are int dx/t)
    assert c[4, 4] == pytest.approx(12 / w**2 * c[0, 0], rel=1e-13)


def test_closed_form_range_warnings_name_parameter_and_range():
    from flexcal.geometry.params import CircularNotchHinge, LeafHinge
    from flexcal.model.hinge import closed_form_range_warnings

    mm = 1e-3
    inside = CircularNotchHinge(radius=5 * mm, thickness=1 * mm, width=10 * mm, block_length=5 * mm)
    assert closed_form_range_warnings(inside, torsion=False) == []
    shallow = CircularNotchHinge(radius=0.4 * mm, thickness=1 * mm, width=10 * mm, block_length=1 * mm)
    (text,) = closed_form_range_warnings(shallow, torsion=False)
    assert "R=0.4 mm" in text and "t/R=2.5" in text and "R < t/2" in text and "t/R <= 1" in text
    edge = CircularNotchHinge(radius=1 * mm, thickness=1 * mm, width=10 * mm, block_length=1 * mm)
    assert closed_form_range_warnings(edge, torsion=False) == []  # t/R = 1 is the edge, still inside
    # torsion: length/width 20/40 = 0.5 is short; 400/40 = 10 is long enough
    short = LeafHinge(length=20 * mm, thickness=4 * mm, width=40 * mm, fillet=6 * mm, block_length=10 * mm)
    (torsion,) = closed_form_range_warnings(short)
    assert "C_rx,Mx" in torsion and "length/width >= 10" in torsion and "is 0.5" in torsion
    long = LeafHinge(length=400 * mm, thickness=4 * mm, width=40 * mm, fillet=6 * mm, block_length=10 * mm)
    assert closed_form_range_warnings(long) == []
