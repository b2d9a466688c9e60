"""Chain cuts and the analytic segment stiffness provider of the virtual prototype."""

import dataclasses

import numpy as np
import pytest

from flexcal.geometry.params import STEEL, FlexureChain, reference_mechanism
from flexcal.validation.prototype import segments as seg


def _circular_notch_rotation(radius, thickness, width, e):
    """C_rz,Mz of a full circular notch, REFERENCES.md closed form (independent of the model)."""
    s = radius / thickness
    bracket = (2 * s**3 * (6 * s**2 + 4 * s + 1) / ((2 * s + 1) * (4 * s + 1) ** 2)
               + 12 * s**4 * (2 * s + 1) / (4 * s + 1) ** 2.5 * np.arctan(np.sqrt(4 * s + 1)))
    return 12.0 / (e * width * radius**2) * bracket


def test_section_nodes_of_the_reference_chain():
    chain = reference_mechanism().chains[0].chain
    x = seg.section_nodes(chain)
    e, l, c, h = chain.end_block_length, chain.hinge_length, chain.connector_length, chain.section
    assert x[1] == pytest.approx(e + l + c / 2)
    assert x[2] == pytest.approx(e + 2 * l + c + h / 2)  # long strut: half a section into it
    assert np.allclose(x + x[::-1], chain.length)  # mirror symmetric
    assert np.all(np.diff(x) > 0)


def test_short_strut_is_cut_at_its_quarter_points():
    chain = reference_mechanism().chains[3].chain  # D1: strut 30 mm, shorter than two half sections
    x = seg.section_nodes(chain)
    strut_start = chain.end_block_length + 2 * chain.hinge_length + chain.connector_length
    assert x[2] - strut_start == pytest.approx(chain.strut_length / 4)
    assert np.all(np.diff(x) > 0)


def test_block_is_a_timoshenko_cantilever():
    chain = reference_mechanism().chains[0].chain
    e_mod, g_mod, nu = STEEL.youngs_modulus, STEEL.shear_modulus, STEEL.poisson_ratio
    h = chain.section
    length = chain.end_block_length
    c = seg.end_compliance(chain, 0.0, length)
    area, inertia = h * h, h**4 / 12
    kappa = 10 * (1 + nu) / (12 + 11 * nu)  # Cowper, rectangle (the model's choice)
    # closed forms of a uniform Timoshenko cantilever; only round-off separates them
    assert c[0, 0] == pytest.approx(length / (e_mod * area), rel=1e-12)
    # as above
    assert c[1, 1] == pytest.approx(length**3 / (3 * e_mod * inertia) + length / (kappa * g_mod * area), rel=1e-12)
    assert c[5, 5] == pytest.approx(length / (e_mod * inertia), rel=1e-12)  # as above
    assert c[1, 5] == pytest.approx(length**2 / (2 * e_mod * inertia), rel=1e-12)  # as above
    assert c[2, 4] == pytest.approx(-length**2 / (2 * e_mod * inertia), rel=1e-12)  # as above


def test_leaf_rotation_compliance_matches_the_published_closed_form():
    chain = dataclasses.replace(reference_mechanism().chains[0].chain, thickness_1=0.004, thickness_2=0.0035)
    e_mod, w, a, l = STEEL.youngs_modulus, chain.width, chain.fillet, chain.hinge_length
    h = chain.section
    block = chain.end_block_length
    x1 = seg.section_nodes(chain)[1]  # block + leaf 1 + half connector
    rigid_parts = (block + chain.connector_length / 2) / (e_mod * h**4 / 12)
    for t, (i, j) in ((chain.thickness_1, (5, 5)), (chain.thickness_2, (4, 4))):
        leaf = 12 * (l - 2 * a) / (e_mod * w * t**3) + _circular_notch_rotation(a, t, w, e_mod)
        if (i, j) == (5, 5):
            got = seg.end_compliance(chain, 0.0, x1)[i, j]
        else:  # leaf 2 (thin in z) lies in [m1, s0] together with half connector and half a section
            x = seg.section_nodes(chain)
            rigid_parts = (chain.connector_length / 2 + h / 2) / (e_mod * h**4 / 12)
            got = seg.end_compliance(chain, x[1], x[2])[i, j]
        # both are exact beam-theory integrals: agreement to round-off (1e-10 relative)
        assert got == pytest.approx(leaf + rigid_parts, rel=1e-10)


def test_slices_compose_to_the_whole_chain():
    """Eq. 1 over the five segments == the whole chain in one slice (series composition)."""
    chain = reference_mechanism().chains[3].chain
    x = seg.section_nodes(chain)
    whole = seg.end_compliance(chain, 0.0, chain.length)
    total = np.zeros((6, 6))
    for a, b in zip(x[:-1], x[1:]):
        move = seg.rigid_transfer(chain.length - b)  # twist at b -> the same rigid motion's twist at L
        total += move @ seg.end_compliance(chain, a, b) @ move.T
    assert np.allclose(total, whole, rtol=1e-12, atol=1e-12 * np.max(np.abs(whole)))  # round-off only


def test_provider_matrix_is_a_free_free_stiffness():
    provider = seg.analytic_provider()
    chain = reference_mechanism().chains[0].chain
    x = seg.section_nodes(chain)
    for a, b in zip(x[:-1], x[1:]):
        k = provider(chain, a, b)
        assert k.shape == (12, 12)
        assert np.allclose(k, k.T, rtol=0, atol=1e-12 * np.max(np.abs(k)))  # symmetric by construction: round-off only
        assert seg.rigid_mode_defect(k, b - a) < 1e-12  # exact expansion: round-off only
        scaled = np.tile(np.r_[np.ones(3), np.full(3, 1 / (b - a))], 2)
        eig = np.linalg.eigvalsh(scaled[:, None] * k * scaled[None, :])
        assert np.all(eig[:6] < 1e-9 * eig[-1]) and np.all(eig[6:] > 1e-9 * eig[-1])  # 6 rigid modes, 6 elastic
        # clamping the start node leaves the end block, whose inverse is the slice compliance
        assert np.allclose(np.linalg.inv(seg.end_stiffness(k)), seg.end_compliance(chain, a, b), rtol=1e-9)


def test_rigid_mode_defect_flags_a_wrong_dof_order():
    chain = reference_mechanism().chains[0].chain
    x = seg.section_nodes(chain)
    k = seg.analytic_provider()(chain, x[0], x[1])
    swapped = np.r_[6:12, 0:6]  # end node first: not the documented order
    # a wrong DOF order: measured 0.021 (the right one: 1e-18)
    assert seg.rigid_mode_defect(k[np.ix_(swapped, swapped)], x[1] - x[0]) > 1e-3


def test_slice_through_a_leaf_is_refused():
    chain = reference_mechanism().chains[0].chain
    with pytest.raises(ValueError, match="cuts through a leaf"):
        seg.end_compliance(chain, 0.0, chain.end_block_length + chain.hinge_length / 2)
