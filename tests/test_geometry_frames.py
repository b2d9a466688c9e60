"""Rigid-body algebra (geometry/frames.py) against mathematics and finite differences:
skew = cross product, exp/log inverse pairs, the adjoint as a group homomorphism, the
closed-form logarithm of small rotations, Jacobians, batched = looped."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from flexcal.fem.condense import frame_axes_transform
from flexcal.geometry import frames as fr

ULP = np.finfo(float).eps  # 2.2e-16, the spacing of doubles near 1


def _twists(rng, n, rotation_scale):
    xi = rng.normal(size=(n, 6))
    xi[:, :3] *= 0.3  # translations ~0.3 m, the size of the mechanism
    xi[:, 3:] *= rotation_scale
    norm = np.linalg.norm(xi[:, 3:], axis=1, keepdims=True)
    xi[:, 3:] *= np.minimum(1.0, 2.5 / norm)  # log is defined for angles below pi
    return xi


def _rotations(rng, n):
    return Rotation.random(n, random_state=rng).as_matrix()


# --- skew, vee, twist transforms -----------------------------------------------------------

def test_skew_matches_cross_product():
    rng = np.random.default_rng(9)
    a, b = rng.standard_normal((2, 5, 3))
    # each entry is a difference of two products of O(1) numbers: a few ulps of ~1
    np.testing.assert_allclose(fr.skew(a) @ b[..., None], np.cross(a, b)[..., None], atol=1e-15)
    np.testing.assert_allclose(fr.cross(a, b), np.cross(a, b), atol=1e-15)  # same products, same bound


def test_skew_is_antisymmetric_and_vee_inverts_it():
    v = np.random.default_rng(10).standard_normal((4, 3, 3))
    s = fr.skew(v)
    assert np.array_equal(s, -np.swapaxes(s, -1, -2))  # built from negated copies: exact
    assert np.array_equal(fr.vee(s), v)  # 0.5 * (v - (-v)): doubling and halving are exact


def test_twist_transform_without_offset_is_a_change_of_axes():
    rot = _rotations(np.random.default_rng(11), 7)
    t = fr.twist_transform(rot, np.zeros(3))
    blocks = np.zeros((7, 6, 6))
    blocks[:, :3, :3] = blocks[:, 3:, 3:] = rot
    assert np.array_equal(t, blocks)  # [0]x R is exactly zero


def test_frame_axes_transform_is_the_twist_transform_with_zero_offset():
    # fem's rotation-only transform: a twist in mesh axes -> the same twist in frame axes
    rng = np.random.default_rng(12)
    frame = _rotations(rng, 1)[0]
    a = frame_axes_transform(frame)
    assert np.array_equal(a, fr.twist_transform(frame.T, np.zeros(3)))  # one rule, exactly
    twist = rng.standard_normal(6)
    # three products of O(1) numbers per component: a few ulps
    np.testing.assert_allclose(a @ twist, np.r_[frame.T @ twist[:3], frame.T @ twist[3:]], atol=4 * ULP)
    with pytest.raises(ValueError, match="orthonormal"):
        frame_axes_transform(2.0 * frame)


def test_twist_transform_moves_a_rigid_twist_between_points():
    # a body rotating with theta about p moves every point q by d_q = d_p + theta x (q - p)
    rng = np.random.default_rng(13)
    rot, p, q = _rotations(rng, 1)[0], rng.normal(size=3), rng.normal(size=3)
    local = rng.normal(size=6)  # twist at p in the local axes
    d_p, theta = rot @ local[:3], rot @ local[3:]  # the same twist in the target axes, still at p
    expected = np.r_[d_p + np.cross(theta, q - p), theta]
    # products and sums of O(1) numbers: 1e-15 is a few ulps
    np.testing.assert_allclose(fr.twist_transform(rot, p - q) @ local, expected, atol=1e-15)


def test_frame_to_point_transform_inverts_the_twist_transform():
    rng = np.random.default_rng(14)
    rot, point = _rotations(rng, 20), 0.3 * rng.normal(size=(20, 3))
    product = fr.frame_to_point_transform(rot, point) @ fr.twist_transform(rot, point)
    # 6-term sums of products of O(0.3..1) numbers: measured 1.1e-15, bound with margin
    np.testing.assert_allclose(product, np.broadcast_to(np.eye(6), product.shape), atol=1e-14)


# --- SO(3) / SE(3) ---------------------------------------------------------------------------

@pytest.mark.parametrize("rotation_scale", [1e-9, 1e-4, 0.05, 0.7])
def test_exp_log_round_trip(rotation_scale):
    xi = _twists(np.random.default_rng(1), 50, rotation_scale)
    back = fr.se3_log(fr.se3_exp(xi))
    # round-off of a 4x4 product on ~0.3 m / ~1 rad entries; relative 1e-13 leaves 1000 ulps
    assert np.allclose(back, xi, rtol=1e-13, atol=1e-15)
    rot = fr.so3_exp(xi[:, 3:])
    assert np.allclose(rot @ np.swapaxes(rot, -1, -2), np.eye(3), atol=1e-15)  # orthonormal to round-off


@pytest.mark.parametrize("rotation_scale", [1e-9, 1e-4, 0.05, 0.7])
def test_exp_of_log_is_the_pose(rotation_scale):
    pose = fr.se3_exp(_twists(np.random.default_rng(15), 50, rotation_scale))
    # entries of the pose are O(1) (rotation) and ~0.3 m; measured <= 4 ulps, 1e-14 leaves margin
    np.testing.assert_allclose(fr.se3_exp(fr.se3_log(pose)), pose, atol=1e-14)


@pytest.mark.parametrize("angle", [1e-12, 1e-9, 1e-6, 1e-3, 0.05, 0.1 - 1e-9, 0.1 + 1e-9, 0.5, 2.0])
def test_log_of_a_rotation_about_one_axis_is_its_angle(angle):
    # closed form: rotation by ``angle`` about z, and scipy's rotation-vector map for other axes
    c, s = np.cos(angle), np.sin(angle)
    about_z = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    axes = np.random.default_rng(16).normal(size=(20, 3))
    phi = angle * axes / np.linalg.norm(axes, axis=1, keepdims=True)
    # relative 1e-13: the Taylor series (truncated after theta^6) err < 1e-13 relative at the
    # 0.1 rad switch (measured 2.7e-14); elsewhere the error is round-off, ~1e-16 relative
    np.testing.assert_allclose(fr.so3_log(about_z), [0.0, 0.0, angle], rtol=1e-13, atol=0)
    np.testing.assert_allclose(fr.so3_log(Rotation.from_rotvec(phi).as_matrix()), phi, rtol=1e-13, atol=1e-13 * angle)  # as above


def test_tiny_rotation_keeps_relative_precision():
    # the arccos form would lose all digits here; atan2 + series keeps them
    phi = np.array([3e-12, -2e-12, 1e-12])
    assert np.allclose(fr.so3_log(fr.so3_exp(phi)), phi, rtol=1e-9, atol=0)  # 1e-9: ~1e-16/|phi| * |R| noise


def test_series_and_closed_forms_meet_at_the_switch():
    # just below and above the switch angle the coefficients must agree to ~1e-9
    # (the closed forms' cancellation error at 0.1 rad, see frames._SERIES_ANGLE)
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    below, above = (fr.se3_left_jacobian_inverse(np.r_[0.1, 0.2, -0.1, a * axis]) for a in (0.1 - 1e-12, 0.1 + 1e-12))
    assert np.allclose(below, above, rtol=1e-9, atol=1e-9)  # cancellation error at 0.1 rad (above)


def test_adjoint_is_a_homomorphism():
    rng = np.random.default_rng(17)
    t1, t2 = (fr.se3_exp(_twists(rng, 30, 1.0)) for _ in range(2))
    # 6x6 products of O(1) entries: measured 2.2e-16, 1e-14 is ~50 ulps of margin
    np.testing.assert_allclose(fr.se3_adjoint(t1 @ t2), fr.se3_adjoint(t1) @ fr.se3_adjoint(t2), atol=1e-14)
    np.testing.assert_allclose(fr.se3_adjoint(fr.se3_inverse(t1)), np.linalg.inv(fr.se3_adjoint(t1)), atol=1e-14)  # as above


def test_adjoint_is_the_twist_transform_of_the_pose():
    t = fr.se3_exp(_twists(np.random.default_rng(18), 10, 1.0))
    assert np.array_equal(fr.se3_adjoint(t), fr.twist_transform(t[:, :3, :3], t[:, :3, 3]))  # same function


def test_adjoint_conjugation():
    rng = np.random.default_rng(2)
    t = fr.se3_exp(_twists(rng, 10, 1.0))
    xi = _twists(rng, 10, 0.5)
    lhs = t @ fr.se3_exp(xi) @ fr.se3_inverse(t)
    rhs = fr.se3_exp(np.einsum("nij,nj->ni", fr.se3_adjoint(t), xi))
    assert np.allclose(lhs, rhs, atol=1e-13)  # round-off of three products of O(1) matrices


def test_small_adjoint_is_the_lie_bracket():
    rng = np.random.default_rng(3)
    a, b = _twists(rng, 2, 1.0)
    hat4 = lambda x: np.block([[fr.skew(x[3:]), x[:3, None]], [np.zeros((1, 4))]])  # noqa: E731
    bracket = hat4(a) @ hat4(b) - hat4(b) @ hat4(a)
    expected = np.r_[bracket[:3, 3], fr.vee(bracket[:3, :3])]
    assert np.allclose(fr.se3_ad(a) @ b, expected, atol=1e-14)  # differences of O(1) products


@pytest.mark.parametrize("rotation_scale", [1e-6, 0.03, 0.5, 1.5])
def test_jacobians_against_finite_differences(rotation_scale):
    rng = np.random.default_rng(4)
    h = 1e-6
    for xi in _twists(rng, 5, rotation_scale):
        j_l_inv, j_r_inv = fr.se3_left_jacobian_inverse(xi), fr.se3_right_jacobian_inverse(xi)
        j_l, j_r = fr.se3_left_jacobian(xi), fr.se3_right_jacobian(xi)
        t = fr.se3_exp(xi)
        for k in range(6):
            e = np.zeros(6)
            e[k] = h
            left = (fr.se3_log(fr.se3_exp(e) @ t) - fr.se3_log(fr.se3_exp(-e) @ t)) / (2 * h)
            right = (fr.se3_log(t @ fr.se3_exp(e)) - fr.se3_log(t @ fr.se3_exp(-e))) / (2 * h)
            # central differences: O(h^2) ~ 1e-12 truncation, ~1e-10 round-off (1e-16 / h)
            assert np.allclose(left, j_l_inv[:, k], rtol=0, atol=1e-8)
            assert np.allclose(right, j_r_inv[:, k], rtol=0, atol=1e-8)  # as above; rtol=0 (default 1e-5 hid it)
            # forward Jacobians: exp(xi + e) = exp(J_l e) exp(xi) = exp(xi) exp(J_r e)
            moved = (fr.se3_exp(xi + e) - fr.se3_exp(xi - e)) / (2 * h)
            assert np.allclose(moved, (fr.se3_exp(j_l[:, k] * h) - fr.se3_exp(-j_l[:, k] * h)) / (2 * h) @ t,
                               rtol=0, atol=1e-8)  # as above
            assert np.allclose(moved, t @ (fr.se3_exp(j_r[:, k] * h) - fr.se3_exp(-j_r[:, k] * h)) / (2 * h),
                               rtol=0, atol=1e-8)  # as above
        assert np.allclose(j_l @ j_l_inv, np.eye(6), atol=1e-12)  # inverse pair to round-off


def test_batched_equals_looped():
    rng = np.random.default_rng(5)
    xi = _twists(rng, 12, 0.4).reshape(3, 4, 6)
    for fn in (fr.se3_exp, fr.se3_left_jacobian_inverse, fr.se3_right_jacobian, fr.se3_ad):
        batched = fn(xi)
        looped = np.array([[fn(x) for x in row] for row in xi])
        assert np.array_equal(batched, looped)
    poses = fr.se3_exp(xi)
    for fn in (fr.se3_log, fr.se3_adjoint, fr.se3_inverse):
        assert np.array_equal(fn(poses), np.array([[fn(p) for p in row] for row in poses]))
    rot, point = poses[..., :3, :3], poses[..., :3, 3]
    for fn in (fr.twist_transform, fr.frame_to_point_transform):
        assert np.array_equal(fn(rot, point), np.array([[fn(r, p) for r, p in zip(*rows)] for rows in zip(rot, point)]))
    assert np.array_equal(fr.skew(point), np.array([[fr.skew(p) for p in row] for row in point]))


def test_chain_rotation_is_the_chain_frame_batched_or_not():
    """x along B - A, y = the roll reference made orthogonal to x (same half-plane), z = x
    cross y; one chain at a time equals all at once (the model's batched call and
    ``ChainPlacement.rotation``'s single one share this function)."""
    rng = np.random.default_rng(7)
    point_a, point_b, reference = rng.normal(size=(3, 5, 3))
    axes = fr.chain_rotation(point_a, point_b, reference)
    axial = (point_b - point_a) / np.linalg.norm(point_b - point_a, axis=1, keepdims=True)
    assert np.allclose(axes[..., 0], axial, rtol=0, atol=4 * ULP)  # normalisation round-off
    assert np.allclose(np.swapaxes(axes, -1, -2) @ axes, np.eye(3), rtol=0, atol=8 * ULP)  # orthonormal to round-off
    assert np.allclose(np.linalg.det(axes), 1.0, rtol=0, atol=8 * ULP)  # right-handed, to round-off
    # y lies in the plane of x and the reference, on the reference's side
    assert np.allclose(np.einsum("ni,ni->n", axes[..., 2], reference), 0.0, rtol=0, atol=16 * ULP)  # as above
    assert np.all(np.einsum("ni,ni->n", axes[..., 1], reference) > 0)
    looped = np.array([fr.chain_rotation(a, b, r) for a, b, r in zip(point_a, point_b, reference)])
    assert np.array_equal(axes, looped)
    with pytest.raises(ValueError, match="coincide"):
        fr.chain_rotation(point_a[0], point_a[0], reference[0])
    with pytest.raises(ValueError, match="parallel"):
        fr.chain_rotation(point_a[0], point_b[0], point_b[0] - point_a[0])


def test_log_near_pi_is_refused():
    with pytest.raises(ValueError, match="pi"):
        fr.so3_log(fr.so3_exp(np.array([0.0, 0.0, np.pi - 1e-9])))
