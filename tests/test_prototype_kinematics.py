"""SE(3) tools of the virtual prototype against mathematics and finite differences."""

import numpy as np
import pytest

from flexcal.validation.prototype import kinematics as kin


def _twists(rng, n, rotation_scale):
    xi = rng.normal(size=(n, 6))
    xi[:, :3] *= 0.3  # translations ~0.3 m, the size of the mechanism
    xi[:, 3:] *= rotation_scale
    norm = np.linalg.norm(xi[:, 3:], axis=1, keepdims=True)
    xi[:, 3:] *= np.minimum(1.0, 2.5 / norm)  # log is defined for angles below pi
    return xi


@pytest.mark.parametrize("rotation_scale", [1e-9, 1e-4, 0.05, 0.7])
def test_exp_log_round_trip(rotation_scale):
    xi = _twists(np.random.default_rng(1), 50, rotation_scale)
    back = kin.se3_log(kin.se3_exp(xi))
    # round-off of a 4x4 product on ~0.3 m / ~1 rad entries; relative 1e-13 leaves 1000 ulps
    assert np.allclose(back, xi, rtol=1e-13, atol=1e-15)
    rot = kin.so3_exp(xi[:, 3:])
    assert np.allclose(rot @ np.swapaxes(rot, -1, -2), np.eye(3), atol=1e-15)  # orthonormal to round-off


def test_tiny_rotation_keeps_relative_precision():
    # the arccos form would lose all digits here; atan2 + series keeps them
    phi = np.array([3e-12, -2e-12, 1e-12])
    assert np.allclose(kin.so3_log(kin.so3_exp(phi)), phi, rtol=1e-9, atol=0)  # 1e-9: ~1e-16/|phi| * |R| noise


def test_series_and_closed_forms_meet_at_the_switch():
    # just below and above the switch angle the coefficients must agree to ~1e-9
    # (the closed forms' cancellation error at 0.1 rad, see kinematics._SERIES_ANGLE)
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    below, above = (kin.se3_left_jacobian_inverse(np.r_[0.1, 0.2, -0.1, a * axis]) for a in (0.1 - 1e-12, 0.1 + 1e-12))
    # the closed forms' cancellation error at 0.1 rad (comment above)
    assert np.allclose(below, above, rtol=1e-9, atol=1e-9)


def test_adjoint_conjugation():
    rng = np.random.default_rng(2)
    t = kin.se3_exp(_twists(rng, 10, 1.0))
    xi = _twists(rng, 10, 0.5)
    lhs = t @ kin.se3_exp(xi) @ kin.se3_inverse(t)
    rhs = kin.se3_exp(np.einsum("nij,nj->ni", kin.se3_adjoint(t), xi))
    assert np.allclose(lhs, rhs, atol=1e-13)  # round-off of three products of O(1) matrices


def test_small_adjoint_is_the_lie_bracket():
    rng = np.random.default_rng(3)
    a, b = _twists(rng, 2, 1.0)
    hat4 = lambda x: np.block([[kin.hat(x[3:]), x[:3, None]], [np.zeros((1, 4))]])
    bracket = hat4(a) @ hat4(b) - hat4(b) @ hat4(a)
    expected = np.r_[bracket[:3, 3], kin.vee(bracket[:3, :3])]
    # products of O(1) numbers: round-off only; rtol=0 (default 1e-5 hid it)
    assert np.allclose(kin.se3_ad(a) @ b, expected, rtol=0, atol=1e-14)


@pytest.mark.parametrize("rotation_scale", [1e-6, 0.03, 0.5, 1.5])
def test_jacobians_against_finite_differences(rotation_scale):
    rng = np.random.default_rng(4)
    h = 1e-6
    for xi in _twists(rng, 5, rotation_scale):
        j_l_inv, j_r_inv = kin.se3_left_jacobian_inverse(xi), kin.se3_right_jacobian_inverse(xi)
        j_l, j_r = kin.se3_left_jacobian(xi), kin.se3_right_jacobian(xi)
        t = kin.se3_exp(xi)
        for k in range(6):
            e = np.zeros(6)
            e[k] = h
            left = (kin.se3_log(kin.se3_exp(e) @ t) - kin.se3_log(kin.se3_exp(-e) @ t)) / (2 * h)
            right = (kin.se3_log(t @ kin.se3_exp(e)) - kin.se3_log(t @ kin.se3_exp(-e))) / (2 * h)
            # central differences: O(h^2) ~ 1e-12 truncation, ~1e-10 round-off (1e-16 / h)
            assert np.allclose(left, j_l_inv[:, k], rtol=0, atol=1e-8)
            # as above; rtol=0 (default 1e-5 hid it)
            assert np.allclose(right, j_r_inv[:, k], rtol=0, atol=1e-8)
            # forward Jacobians: exp(xi + e) = exp(J_l e) exp(xi) = exp(xi) exp(J_r e)
            moved = (kin.se3_exp(xi + e) - kin.se3_exp(xi - e)) / (2 * h)
            assert np.allclose(moved, (kin.se3_exp(j_l[:, k] * h) - kin.se3_exp(-j_l[:, k] * h)) / (2 * h) @ t,
                               rtol=0, atol=1e-8)  # as above
            assert np.allclose(moved, t @ (kin.se3_exp(j_r[:, k] * h) - kin.se3_exp(-j_r[:, k] * h)) / (2 * h),
                               rtol=0, atol=1e-8)  # as above
        assert np.allclose(j_l @ j_l_inv, np.eye(6), rtol=0, atol=1e-12)  # inverse pair to round-off


def test_batched_equals_looped():
    xi = _twists(np.random.default_rng(5), 12, 0.4).reshape(3, 4, 6)
    for fn in (kin.se3_exp, kin.se3_left_jacobian_inverse, kin.se3_right_jacobian, kin.se3_ad):
        batched = fn(xi)
        looped = np.array([[fn(x) for x in row] for row in xi])
        assert np.array_equal(batched, looped)


def test_orthonormalize_removes_drift():
    t = kin.se3_exp(np.r_[0.1, 0.2, 0.3, 0.4, -0.2, 0.1])
    drifted = t.copy()
    drifted[:3, :3] *= 1 + 1e-9
    fixed = kin.orthonormalize(drifted)
    # a rotation scaled by 1 + 1e-9, orthonormalized: round-off only; rtol=0 (default 1e-5 hid it)
    assert np.allclose(fixed[:3, :3] @ fixed[:3, :3].T, np.eye(3), rtol=0, atol=1e-15)
    assert np.allclose(fixed, t, rtol=0, atol=1e-14)  # as above


def test_log_near_pi_is_refused():
    with pytest.raises(ValueError, match="pi"):
        kin.so3_log(kin.so3_exp(np.array([0.0, 0.0, np.pi - 1e-9])))
