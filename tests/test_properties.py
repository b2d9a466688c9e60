"""Property-based tests (hypothesis) of invariants over random valid inputs: geometry,
closed-form model, FEM element. Each stays small (max_examples) so the file runs in
seconds; they complement the worked examples of test_params, test_model_hinge,
test_fem_elements (which hold the specific numbers)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from flexcal.fem.elements import elasticity_matrix, element_stiffness, element_strain_at_nodes, element_volumes
from flexcal.geometry.exact import end_planes, exact_volume, thin_sections
from flexcal.geometry.params import STEEL, CircularNotchHinge, FlexureChain, LeafHinge, Material
from flexcal.model import hinge as closed_form
from flexcal.model.chain import chain_compliance_matrix, hinge_part_compliance
from helpers import well_shaped_p2_tets

mm = 1e-3
FAST = settings(max_examples=25, deadline=None)

notches = st.builds(CircularNotchHinge, radius=st.floats(0.5 * mm, 20 * mm), thickness=st.floats(0.1 * mm, 10 * mm),
                    width=st.floats(1 * mm, 50 * mm), block_length=st.floats(0.5 * mm, 20 * mm))


@st.composite
def leaves(draw):
    length = draw(st.floats(2 * mm, 60 * mm))
    return LeafHinge(length=length, thickness=draw(st.floats(0.1 * mm, 10 * mm)), width=draw(st.floats(1 * mm, 60 * mm)),
                     fillet=draw(st.floats(0.0, 0.5)) * length, block_length=draw(st.floats(0.5 * mm, 20 * mm)))


@st.composite
def chains(draw):
    hinge_length = draw(st.floats(5 * mm, 30 * mm))
    fillet = draw(st.floats(0.0, 0.5)) * hinge_length
    section = draw(st.floats(30 * mm, 80 * mm))
    width = draw(st.floats(0.3, 1.0)) * section
    room = section - 2 * fillet  # t + 2a <= section
    assume(room > 0.6 * mm)
    t1, t2 = (draw(st.floats(0.5 * mm, min(8 * mm, room))) for _ in range(2))
    minimum = 2 * 10 * mm + 4 * hinge_length + 2 * 10 * mm
    return FlexureChain(length=minimum + draw(st.floats(1 * mm, 400 * mm)), hinge_length=hinge_length, width=width,
                        fillet=fillet, thickness_1=t1, thickness_2=t2, section=section)


# ----------------------------------------------------------------------------- geometry

@FAST
@given(hinge=st.one_of(notches, leaves()))
def test_hinge_exact_surfaces(hinge):
    ends = end_planes(hinge)
    fixed, free = ends["fixed"], ends["free"]
    # end faces at -/+ total_length / 2 with outward normals
    # end planes at -/+ total_length / 2: round-off only
    assert free[0][0] - fixed[0][0] == pytest.approx(hinge.total_length, rel=1e-12)
    np.testing.assert_array_equal(fixed[1], [-1, 0, 0])
    np.testing.assert_array_equal(free[1], [1, 0, 0])
    (section,) = thin_sections(hinge)
    x = np.linspace(section.x0, section.x1, 2001)
    t = section.thickness(x)
    # the thinnest section is t, at the neck; the profile never exceeds the block height
    # rel: the cancellation bound below
    assert section.thickness(np.array([section.neck_x]))[0] == pytest.approx(hinge.thickness, rel=1e-12)
    # t + 2R - 2 sqrt(R^2 - x^2) cancels at the neck: relative round-off <= eps 4R/t ~ 2e-13 (R/t <= 200)
    assert t.min() >= hinge.thickness * (1 - 1e-12) and t.max() <= hinge.height * (1 + 1e-12)
    # symmetric about the neck, thickening away from it
    # same cancellation bound as above; measured 4e-14 over 100 draws (was 1e-9)
    np.testing.assert_allclose(t, t[::-1], rtol=1e-12)
    half = t[1000:]
    # monotone up to round-off of t (a few ulp of the block height)
    assert np.all(np.diff(half) >= -1e-15 * hinge.height)
    # the volume formula equals the integral of the profile (adaptive quadrature, split at
    # the kinks of a filleted leaf; asked for 1e-11, so 1e-9 is far above its error)
    from scipy.integrate import quad

    kinks = [section.x0 + hinge.fillet, section.x1 - hinge.fillet] if isinstance(hinge, LeafHinge) else None
    area, _ = quad(lambda s: float(section.thickness(np.array([s]))[0]), section.x0, section.x1, points=kinks,
                   epsabs=0.0, epsrel=1e-11, limit=200)
    integrated = hinge.width * area + 2 * hinge.block_length * hinge.height * hinge.width
    assert exact_volume(hinge) == pytest.approx(integrated, rel=1e-9)  # quad asked for 1e-11 (see above)


@FAST
@given(chain=chains())
def test_chain_segments_tile_the_length(chain):
    segments = chain.segments()
    # sum of segment lengths: round-off only
    assert segments[0][1] == 0.0 and segments[-1][2] == pytest.approx(chain.length, rel=1e-12)
    for (_, _, end), (_, start, _) in zip(segments, segments[1:]):
        assert start == end
    kinds = [k for k, _, _ in segments]
    assert kinds == kinds[::-1]  # mirror-symmetric about the middle
    assert chain.leaf(1).thickness == chain.thickness_1 and chain.leaf(2).thickness == chain.thickness_2
    assert [s.name for s in thin_sections(chain)] and len(thin_sections(chain)) == 4


@FAST
@given(field=st.sampled_from(["radius", "thickness", "width", "block_length"]),
       value=st.one_of(st.floats(-1.0, 0.0), st.just(float("nan")), st.just(float("inf"))))
def test_invalid_notch_raises_value_error_naming_the_field(field, value):
    good = dict(radius=5 * mm, thickness=1 * mm, width=10 * mm, block_length=5 * mm)
    with pytest.raises(ValueError, match=field):
        CircularNotchHinge(**{**good, field: value})


@FAST
@given(length=st.floats(2 * mm, 60 * mm), excess=st.floats(1e-6, 2.0))
def test_fillets_longer_than_half_the_leaf_are_refused(length, excess):
    with pytest.raises(ValueError, match="fillet"):
        LeafHinge(length=length, thickness=1 * mm, width=10 * mm, fillet=0.5 * length * (1 + excess), block_length=mm)


# ----------------------------------------------------------------------------- closed-form model

@FAST
@given(hinge=notches, youngs=st.floats(50e9, 400e9), scale=st.floats(0.2, 5.0))
def test_notch_compliance_spd_and_scales_like_the_formulas(hinge, youngs, scale):
    material = Material(youngs_modulus=youngs)
    c = closed_form.circular_notch_compliance(hinge.radius, hinge.thickness, hinge.width, material)
    np.testing.assert_allclose(c, c.T, rtol=0, atol=1e-14 * np.abs(c).max())  # symmetric up to rounding
    d = np.sqrt(np.diag(c))
    assert np.linalg.eigvalsh(c / np.outer(d, d))[0] > 0  # unit-free: SPD whatever the scales
    # every entry is an integral of 1/E (G = E / 2(1 + nu) at fixed nu): C ~ 1/E exactly
    stiffer = closed_form.circular_notch_compliance(hinge.radius, hinge.thickness, hinge.width,
                                                    dataclasses.replace(material, youngs_modulus=scale * youngs))
    # C ~ 1/E exactly: round-off only
    np.testing.assert_allclose(stiffer, c / scale, rtol=1e-12, atol=1e-12 * np.abs(c).max())
    # in-plane bending (I = b t(x)^3 / 12) and axial (A = b t(x)) entries ~ 1/b
    wider = closed_form.circular_notch_compliance(hinge.radius, hinge.thickness, scale * hinge.width, material)
    for i in (0, 1, 5):
        assert wider[i, i] == pytest.approx(c[i, i] / scale, rel=1e-12)  # ~ 1/b exactly: round-off only
    # C_rz,Mz is the exact Paros-Weisbord/Lobontiu integral
    assert c[5, 5] == pytest.approx(float(closed_form.circular_notch_rotation_compliance(
        # the same integral by two code paths: round-off only
        hinge.radius, hinge.thickness, hinge.width, youngs)), rel=1e-12)
    thinner = closed_form.circular_notch_compliance(hinge.radius, 0.9 * hinge.thickness, hinge.width, material)
    assert thinner[5, 5] > c[5, 5]


@FAST
@given(hinge=st.one_of(notches, leaves()))
def test_hinge_part_compliance_is_spd(hinge):
    c = hinge_part_compliance(hinge, STEEL)
    d = np.sqrt(np.diag(c))
    # symmetric up to rounding (measured exactly symmetric)
    np.testing.assert_allclose(c, c.T, rtol=0, atol=1e-13 * np.abs(c).max())
    assert np.linalg.eigvalsh(c / np.outer(d, d))[0] > 0  # unit-free: SPD whatever the scales


@settings(max_examples=10, deadline=None)
@given(chain=chains(), scale=st.floats(0.2, 5.0))
def test_chain_compliance_spd_and_inverse_in_e(chain, scale):
    c = chain_compliance_matrix(chain, STEEL)
    d = np.sqrt(np.diag(c))
    assert np.linalg.eigvalsh(c / np.outer(d, d))[0] > 0
    stiffer = chain_compliance_matrix(chain, dataclasses.replace(STEEL, youngs_modulus=scale * STEEL.youngs_modulus))
    # C ~ 1/E exactly: measured 4e-16 over 30 draws (was rtol 1e-10)
    np.testing.assert_allclose(stiffer, c / scale, rtol=1e-12, atol=1e-12 * np.abs(c).max())


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_candidates=st.integers(1, 3), n_points=st.integers(1, 4))
def test_forward_batched_equals_looped_and_inverse_round_trips(seed, n_candidates, n_points):
    from flexcal.model.forward import forward
    from flexcal.model.inverse import inverse
    from flexcal.model.parameters import parameter_space
    from flexcal.model.trajectory import standard_trajectory

    space = parameter_space()
    rng = np.random.default_rng(seed)
    values = space.from_unit(rng.random((n_candidates, 45)))
    mu = [space.index(f"D{k}.mu") for k in (1, 2, 3)]
    values[:, mu] = np.minimum(values[:, mu], 0.95)  # keep a gain inside the clearance gap (invertible)
    trajectory = standard_trajectory()
    points = rng.choice(len(trajectory.inputs), n_points, replace=False)
    inputs, directions = trajectory.inputs[points], trajectory.directions[points]
    batched = forward(values, inputs, directions)
    for c in range(n_candidates):
        looped = np.stack([forward(values[c], inputs[j:j + 1], directions[j:j + 1]).angles[0, 0]
                           for j in range(n_points)])
        np.testing.assert_allclose(batched.angles[c], looped, rtol=0, atol=1e-12)  # same solver, same tolerance
    result = inverse(batched.angles[0], directions, space_values=values[0])
    # the solver stops at 1e-12 rad; 1e-9 m / 1e-9 rad is the acceptance of docs/model.md
    np.testing.assert_allclose(result.inputs, inputs, rtol=0, atol=1e-9)


# ----------------------------------------------------------------------------- FEM element

def _tet(rng, curved: bool) -> np.ndarray:
    """One well-shaped P2 tet (10, 3) [m] (tests/helpers.py)."""
    return well_shaped_p2_tets(rng, 1, curved)[0]


@FAST
@given(seed=st.integers(0, 2**32 - 1), poisson=st.floats(0.0, 0.45), curved=st.booleans())
def test_element_patch_test(seed, poisson, curved):
    """A linear displacement field u = a + B x is reproduced exactly: constant strain
    sym(B) at every node, and strain energy u.K.u = V eps.D.eps (isoparametric P2)."""
    rng = np.random.default_rng(seed)
    coords = _tet(rng, curved)
    material = Material(poisson_ratio=poisson)
    a, B = rng.standard_normal(3) * 1e-4, rng.standard_normal((3, 3)) * 1e-3
    u = a + coords @ B.T  # (10, 3) [m]
    strain = element_strain_at_nodes(coords[None], u[None])[0]  # (10, 6)
    expected = np.array([B[0, 0], B[1, 1], B[2, 2], B[1, 2] + B[2, 1], B[0, 2] + B[2, 0], B[0, 1] + B[1, 0]])
    # exact up to round-off of inverting J (entries ~1e-2 m): 1e-10 of the strain scale
    np.testing.assert_allclose(strain, np.broadcast_to(expected, (10, 6)), rtol=0, atol=1e-10 * np.abs(B).max())
    K = element_stiffness(coords[None], material)[0]
    energy = u.ravel() @ K @ u.ravel()
    volume = element_volumes(coords[None])[0]
    # u.K.u cancels the rigid part a (~10x B x): measured <= 1e-12 over 200 draws (was 1e-9)
    assert energy == pytest.approx(volume * expected @ elasticity_matrix(material) @ expected, rel=1e-10)


@FAST
@given(seed=st.integers(0, 2**32 - 1), curved=st.booleans(), scale=st.floats(0.1, 10.0))
def test_element_stiffness_scales_with_size_and_modulus(seed, curved, scale):
    """K of a tet scaled by s is s K (stiffness ~ E L); K ~ E at fixed nu."""
    coords = _tet(np.random.default_rng(seed), curved)
    K = element_stiffness(coords[None], STEEL)[0]
    bigger = element_stiffness(scale * coords[None], STEEL)[0]
    # K ~ s K up to round-off of the scaled coordinates: measured 1e-15 of max|K| (was rtol 1e-9, atol 1e-12)
    np.testing.assert_allclose(bigger, scale * K, rtol=1e-12, atol=1e-13 * scale * np.abs(K).max())
    softer = element_stiffness(coords[None], dataclasses.replace(STEEL, youngs_modulus=STEEL.youngs_modulus / scale))[0]
    # K ~ E exactly: round-off only
    np.testing.assert_allclose(softer, K / scale, rtol=1e-12, atol=1e-14 * np.abs(K).max() / scale)
    assert math.isfinite(float(np.abs(K).max()))
