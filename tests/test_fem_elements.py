"""P2 tet element: shape functions, quadrature, element stiffness."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flexcal.fem.elements import (
    EDGES,
    REFERENCE_NODES,
    TET_4POINT,
    TET_14POINT,
    affine_elements,
    elasticity_matrix,
    element_stiffness,
    element_volumes,
    shape_functions,
    shape_gradients,
    strain_displacement,
    _physical_gradients,
)
from flexcal.fem.coupling import rigid_body_modes
from flexcal.geometry.params import Material

from helpers import well_shaped_p2_tets as _random_tets

STEEL = Material()


def _monomial_integral(i: int, j: int, k: int) -> float:
    """Exact integral of xi^i eta^j zeta^k over the reference tet."""
    return math.factorial(i) * math.factorial(j) * math.factorial(k) / math.factorial(i + j + k + 3)


@pytest.mark.parametrize("rule", [TET_4POINT, TET_14POINT], ids=["4-point", "14-point"])
def test_quadrature_exact_to_its_degree(rule):
    for degree in range(rule.degree + 1):
        for i in range(degree + 1):
            for j in range(degree + 1 - i):
                k = degree - i - j
                x, y, z = rule.points.T
                value = rule.weights @ (x**i * y**j * z**k)
                # round-off of a sum of <= 14 terms of size <= 1: 1e-14 relative
                assert value == pytest.approx(_monomial_integral(i, j, k), rel=1e-14, abs=1e-16)


def test_quadrature_degree_is_not_higher_than_claimed():
    """The 4-point rule must miss some degree-3 monomial (else the degree claim is
    meaningless as a test)."""
    x, y, z = TET_4POINT.points.T
    # it misses by 3.6e-4 (of 1/120): far above round-off, far below a wrong rule
    assert abs(TET_4POINT.weights @ x**3 - _monomial_integral(3, 0, 0)) > 1e-4


def test_shape_functions_are_nodal_and_a_partition_of_unity():
    N = shape_functions(REFERENCE_NODES)
    np.testing.assert_allclose(N, np.eye(10), atol=1e-15)  # exact arithmetic on 0, 1/2, 1
    points = np.random.default_rng(0).dirichlet(np.ones(4), size=50)[:, 1:]
    # round-off of a sum of 10 terms <= 1
    np.testing.assert_allclose(shape_functions(points).sum(axis=1), 1.0, atol=1e-14)
    # round-off of 10 gradient terms of size <= 4
    np.testing.assert_allclose(shape_gradients(points).sum(axis=1), 0.0, atol=1e-13)


def test_shape_gradients_match_finite_differences():
    points = np.random.default_rng(1).dirichlet(np.ones(4), size=20)[:, 1:]
    step = 1e-6
    for axis in range(3):
        shift = np.zeros(3)
        shift[axis] = step
        numeric = (shape_functions(points + shift) - shape_functions(points - shift)) / (2 * step)
        # central differences of quadratics are exact up to round-off ~ eps / step = 1e-10
        np.testing.assert_allclose(shape_gradients(points)[:, :, axis], numeric, atol=1e-8)


@pytest.mark.parametrize("curved", [False, True])
def test_isotropic_formula_equals_btdb(curved):
    """The fast isotropic form equals the textbook sum of B^T D B w det J."""
    coords = _random_tets(np.random.default_rng(2), 5, curved)
    rule = TET_14POINT if curved else TET_4POINT
    G, det = _physical_gradients(coords, rule)
    B = strain_displacement(G)  # (e, q, 6, 30)
    D = elasticity_matrix(STEEL)
    reference = np.einsum("eqki,kl,eqlj,eq->eij", B, D, B, det * rule.weights)
    K = element_stiffness(coords, STEEL, rule)
    # two summation orders of the same ~100 terms: 1e-13 of the largest entry
    np.testing.assert_allclose(K, reference, atol=1e-13 * np.abs(reference).max())


def test_batched_equals_looped():
    coords = _random_tets(np.random.default_rng(3), 7, curved=True)
    batched = element_stiffness(coords, STEEL)
    looped = np.stack([element_stiffness(c[None], STEEL)[0] for c in coords])
    # same arithmetic, batched: round-off only
    np.testing.assert_allclose(batched, looped, rtol=0, atol=1e-14 * np.abs(looped).max())


def test_automatic_rule_choice():
    coords = np.concatenate([_random_tets(np.random.default_rng(4), 3, False), _random_tets(np.random.default_rng(5), 3, True)])
    np.testing.assert_array_equal(affine_elements(coords), [True] * 3 + [False] * 3)
    auto = element_stiffness(coords, STEEL)
    # the same rule chosen automatically: round-off only
    np.testing.assert_allclose(auto[:3], element_stiffness(coords[:3], STEEL, TET_4POINT), rtol=1e-13, atol=0)
    # as above
    np.testing.assert_allclose(auto[3:], element_stiffness(coords[3:], STEEL, TET_14POINT), rtol=1e-13, atol=0)
    # on straight tets both rules are exact: they agree to round-off
    scale = np.abs(auto[:3]).max()
    # round-off (see the comment above)
    np.testing.assert_allclose(element_stiffness(coords[:3], STEEL, TET_14POINT), auto[:3], atol=1e-12 * scale)


def test_volume_of_straight_tet():
    coords = _random_tets(np.random.default_rng(6), 4, curved=False)
    exact = np.linalg.det(coords[:, 1:4] - coords[:, :1]) / 6.0
    # det / 6 vs the quadrature's volume: round-off only
    np.testing.assert_allclose(element_volumes(coords), exact, rtol=1e-13)


def test_rotated_element_has_rotated_stiffness():
    rng = np.random.default_rng(7)
    coords = _random_tets(rng, 1, curved=True)[0]
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    K = element_stiffness(coords[None], STEEL)[0]
    K_rot = element_stiffness((coords @ Q.T)[None], STEEL)[0]
    R = np.kron(np.eye(10), Q)
    # frame invariance of an isotropic law; round-off of ~ 1e3 operations
    np.testing.assert_allclose(K_rot, R @ K @ R.T, atol=1e-12 * np.abs(K).max())


def test_inverted_tet_is_rejected_with_advice():
    coords = _random_tets(np.random.default_rng(8), 1, curved=False)
    swapped = coords.copy()
    swapped[0, [1, 2]] = coords[0, [2, 1]]
    swapped[0, 4:] = 0.5 * (swapped[0, EDGES[:, 0]] + swapped[0, EDGES[:, 1]])
    with pytest.raises(ValueError, match="non-positive Jacobian"):
        element_stiffness(swapped, STEEL)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    poisson=st.floats(0.0, 0.45),
    curved=st.booleans(),
)
def test_element_stiffness_is_symmetric_psd_with_rigid_null_space(seed, poisson, curved):
    coords = _random_tets(np.random.default_rng(seed), 1, curved)[0]
    material = Material(poisson_ratio=poisson)
    K = element_stiffness(coords[None], material)[0]
    scale = np.abs(K).max()
    np.testing.assert_allclose(K, K.T, atol=1e-14 * scale)  # round-off of the symmetric form
    modes = rigid_body_modes(coords)  # (30, 6), rotations about the centroid [m/rad]
    modes = modes / np.linalg.norm(modes, axis=0)
    # K r = 0 up to round-off: ~1e-15 relative to ||K|| (x 30 terms)
    assert np.abs(K @ modes).max() <= 1e-12 * scale
    eigenvalues = np.linalg.eigvalsh(K)
    assert eigenvalues[0] >= -1e-12 * scale  # PSD up to eigvalsh round-off ~ eps ||K|| sqrt(30)
    # exactly 6 zero modes: the 7th eigenvalue is a real deformation mode, far above round-off
    assert eigenvalues[6] > 1e-6 * scale
