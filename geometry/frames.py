"""Rigid-body algebra, once for fem, model and validation: skew matrices, 6x6 twist
transforms (the SE(3) adjoint), SE(3)/SO(3) exp, log, inverse and Jacobians, and the
chain axes (a chain's local frame from its end points).

Twists are ``[d; theta]`` (..., 6): translation [m] first, rotation [rad] second, ordered
x, y, z (``ux, uy, uz, rx, ry, rz``); wrenches ``[F; M]`` ([N], [N m]). A twist ``t_p`` of
a body expressed at point ``p`` in a frame with axes ``R`` (columns, in the target frame)
is the target-frame twist at ``q``

    t_q = T t_p,   T = twist_transform(R, r) = [[R, [r]x R], [0, R]],   r = p - q

and a target-frame wrench at ``q`` acts at ``p`` in the local frame as ``T^T w_q``. The
sign of ``r`` matters: ``q - p`` flips the coupling blocks.

Poses are homogeneous matrices ``T = [[R, p], [0, 1]]`` (..., 4, 4): ``R`` rotates body
axes into the parent frame, ``p`` [m] is the body origin in the parent frame, and the
adjoint of the pose is the twist transform above, ``Ad(T) = twist_transform(R, p)``.
``exp(xi)`` is the pose reached by moving with the constant body velocity ``xi`` for unit
time; ``log`` is its inverse (rotation angles below pi). Perturbations on the right
(body frame) are ``T <- T exp(delta)``; the Jacobians follow Barfoot, *State Estimation
for Robotics* (2017), Sec. 7.1.5, with the same translation-first ordering:

    log(exp(xi) exp(delta)) = xi + J_r(xi)^-1 delta + O(delta^2)
    log(exp(delta) exp(xi)) = xi + J_l(xi)^-1 delta + O(delta^2)
    T exp(xi) T^-1 = exp(Ad(T) xi)

Every function is pure and batch-first: leading dimensions broadcast. Near-zero angles
use Taylor series, so nothing loses precision for the micro-radian deformations of
flexure segments (the closed forms cancel catastrophically there). numpy only.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "skew",
    "vee",
    "cross",
    "twist_transform",
    "frame_to_point_transform",
    "rotation_about_x",
    "chain_rotation",
    "so3_exp",
    "so3_log",
    "so3_left_jacobian",
    "so3_right_jacobian",
    "so3_left_jacobian_inverse",
    "pose",
    "translation_pose",
    "se3_exp",
    "se3_log",
    "se3_inverse",
    "se3_adjoint",
    "se3_ad",
    "se3_left_jacobian",
    "se3_right_jacobian",
    "se3_left_jacobian_inverse",
    "se3_right_jacobian_inverse",
]

# Below this angle [rad] the trigonometric coefficients use their Taylor series; the
# series below are truncated after theta^6, whose error at 0.1 rad is < 1e-13 relative,
# while the closed forms lose at most ~1e-9 relative just above it (module docstring).
_SERIES_ANGLE = 0.1


# --- cross products and twist transforms -------------------------------------------------

def skew(vector: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[v]x`` (..., 3, 3) of ``vector`` (..., 3): ``[v]x w = v x w``.

    Same unit as ``vector``. (Barfoot's ``hat`` of a 3-vector.)
    """
    v = np.asarray(vector, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def vee(matrix: np.ndarray) -> np.ndarray:
    """Inverse of ``skew`` for the skew part of ``matrix`` (..., 3, 3) -> (..., 3)."""
    m = np.asarray(matrix, dtype=float)
    return 0.5 * np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
                          axis=-1)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` over the last axis (..., 3), broadcast; ``np.cross`` without its per-call overhead."""
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def twist_transform(rotation: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Adjoint ``T = [[R, [r]x R], [0, R]]`` (..., 6, 6).

    rotation (..., 3, 3): columns are the local axes in the target frame; offset (..., 3) [m]:
    ``r = p - q``, the source point ``p`` minus the target point ``q`` in the target frame.
    ``T`` maps a local twist at ``p`` to the target-frame twist at ``q``; ``T^T`` maps a
    target-frame wrench at ``q`` to the local wrench at ``p``. A zero offset gives a pure
    change of axes, ``block-diag(R, R)``.
    """
    rot = np.asarray(rotation, dtype=float)
    r = np.asarray(offset, dtype=float)
    shape = np.broadcast_shapes(rot.shape[:-2], r.shape[:-1])
    out = np.zeros(shape + (6, 6))
    out[..., :3, :3] = rot
    out[..., 3:, 3:] = rot
    out[..., :3, 3:] = skew(r) @ rot
    return out


def frame_to_point_transform(rotation: np.ndarray, point: np.ndarray) -> np.ndarray:
    """``J = [[R^T, -R^T [p]x], [0, R^T]]`` (..., 6, 6): a twist at the origin -> the twist
    of a rigidly attached point ``p`` [m] in the local frame ``R`` (columns = local axes).

    The inverse of ``twist_transform(R, p)``. Row k of ``-R^T [p]x`` is ``(p x r_k)^T`` with
    r_k the k-th local axis (column k of R).
    """
    rot = np.asarray(rotation, dtype=float)
    p = np.asarray(point, dtype=float)
    axes = np.swapaxes(rot, -1, -2)  # rows = local axes r_k
    shape = np.broadcast_shapes(rot.shape[:-2], p.shape[:-1])
    out = np.zeros(shape + (6, 6))
    out[..., :3, :3] = axes
    out[..., 3:, 3:] = axes
    out[..., :3, 3:] = cross(p[..., None, :], axes)
    return out


def rotation_about_x(angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` [rad] about x (columns = rotated axes)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def chain_rotation(point_a: np.ndarray, point_b: np.ndarray, roll_reference: np.ndarray) -> np.ndarray:
    """A chain's local axes (..., 3, 3): columns x, y, z in the global frame, batched.

    x points from A to B ([m] inputs), y is ``roll_reference`` made orthogonal to x,
    z = x cross y. The model's chain frames (Eq. 2-3) and ``ChainPlacement.rotation``.
    Raises ``ValueError`` if A = B or the reference is parallel to the axis.
    """
    axis = np.asarray(point_b, dtype=float) - np.asarray(point_a, dtype=float)
    length = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(length <= 0):
        raise ValueError("chain end points A and B coincide; a chain needs a length > 0")
    x = axis / length
    ref = np.broadcast_to(np.asarray(roll_reference, dtype=float), x.shape)
    y = ref - np.sum(ref * x, axis=-1, keepdims=True) * x
    norm = np.linalg.norm(y, axis=-1, keepdims=True)
    if np.any(norm < 1e-9):
        raise ValueError("roll_reference is parallel to the chain axis; choose another")
    y = y / norm
    return np.stack([x, y, cross(x, y)], axis=-1)


# --- SO(3) ----------------------------------------------------------------------------------

_CLOSED = {
    "a": lambda t, s, c: s / t,
    "b": lambda t, s, c: (1.0 - c) / t**2,
    "c": lambda t, s, c: (t - s) / t**3,
    "d": lambda t, s, c: (t**2 + 2.0 * c - 2.0) / (2.0 * t**4),
    "e": lambda t, s, c: (2.0 * t - 3.0 * s + t * c) / (2.0 * t**5),
    "f": lambda t, s, c: 1.0 / t**2 - (1.0 + c) / (2.0 * t * s),
}
_SERIES = {  # Taylor coefficients in t^2, up to t^6
    "a": (1.0, -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0),
    "b": (0.5, -1.0 / 24.0, 1.0 / 720.0, -1.0 / 40320.0),
    "c": (1.0 / 6.0, -1.0 / 120.0, 1.0 / 5040.0, -1.0 / 362880.0),
    "d": (1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0),
    "e": (1.0 / 120.0, -1.0 / 2520.0, 1.0 / 120960.0, -1.0 / 9979200.0),
    "f": (1.0 / 12.0, 1.0 / 720.0, 1.0 / 30240.0, 1.0 / 1209600.0),
}


def _coefficients(theta: np.ndarray, names: str = "abcdef") -> dict[str, np.ndarray]:
    """Trigonometric coefficients of the exp/log/Jacobian closed forms, series near 0.

    a = sin t / t, b = (1 - cos t)/t^2, c = (t - sin t)/t^3, d = (t^2 + 2 cos t - 2)/(2 t^4),
    e = (2 t - 3 sin t + t cos t)/(2 t^5), f = (1/t^2 - (1 + cos t)/(2 t sin t)).
    Only the coefficients in ``names`` are computed.
    """
    t = np.asarray(theta, dtype=float)
    small = t < _SERIES_ANGLE
    out = {}
    if np.any(small):
        t2 = t * t
        for n in names:
            k0, k1, k2, k3 = _SERIES[n]
            out[n] = k0 + t2 * (k1 + t2 * (k2 + t2 * k3))
        if np.all(small):
            return out
    ts = np.where(small, 1.0, t)  # safe argument for the closed forms
    s, c = np.sin(ts), np.cos(ts)
    for n in names:
        closed = _CLOSED[n](ts, s, c)
        out[n] = np.where(small, out[n], closed) if n in out else closed
    return out


def so3_exp(phi: np.ndarray) -> np.ndarray:
    """Rotation matrix (..., 3, 3) of the rotation vector ``phi`` (..., 3) [rad] (Rodrigues)."""
    phi = np.asarray(phi, dtype=float)
    theta = np.linalg.norm(phi, axis=-1)
    k = _coefficients(theta, "ab")
    w = skew(phi)
    return np.eye(3) + k["a"][..., None, None] * w + k["b"][..., None, None] * (w @ w)


def so3_log(rotation: np.ndarray) -> np.ndarray:
    """Rotation vector (..., 3) [rad] of ``rotation`` (..., 3, 3), angle in [0, pi).

    Uses ``theta = atan2(|w|, (tr R - 1)/2)`` with ``w = vee(R - R^T)/2 = sin(theta) axis``,
    accurate for tiny angles. Angles within 1e-6 rad of pi raise ``ValueError`` (no flexure
    gets there; a rotation that large means a broken input).
    """
    r = np.asarray(rotation, dtype=float)
    w = vee(r)  # = sin(theta) * axis
    sin_t = np.linalg.norm(w, axis=-1)
    cos_t = 0.5 * (np.trace(r, axis1=-2, axis2=-1) - 1.0)
    theta = np.arctan2(sin_t, cos_t)
    if np.any(theta > np.pi - 1e-6):
        raise ValueError("rotation angle too close to pi for so3_log; the pose is far outside any flexure's range")
    return (1.0 / _coefficients(theta, "a")["a"])[..., None] * w


def so3_left_jacobian(phi: np.ndarray) -> np.ndarray:
    """J_l(phi) = I + b [phi]x + c [phi]x^2 (..., 3, 3) (coefficients b, c of ``_coefficients``)."""
    phi = np.asarray(phi, dtype=float)
    k = _coefficients(np.linalg.norm(phi, axis=-1), "bc")
    w = skew(phi)
    return np.eye(3) + k["b"][..., None, None] * w + k["c"][..., None, None] * (w @ w)


def so3_right_jacobian(phi: np.ndarray) -> np.ndarray:
    """J_r(phi) = J_l(-phi) (..., 3, 3)."""
    return so3_left_jacobian(-np.asarray(phi, dtype=float))


def so3_left_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """J_l(phi)^-1 = I - [phi]x/2 + f [phi]x^2 (..., 3, 3)."""
    phi = np.asarray(phi, dtype=float)
    k = _coefficients(np.linalg.norm(phi, axis=-1), "f")
    w = skew(phi)
    return np.eye(3) - 0.5 * w + k["f"][..., None, None] * (w @ w)


# --- SE(3) ----------------------------------------------------------------------------------

def pose(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Homogeneous pose (..., 4, 4) from ``rotation`` (..., 3, 3) and ``translation`` (..., 3) [m]."""
    r = np.asarray(rotation, dtype=float)
    p = np.asarray(translation, dtype=float)
    shape = np.broadcast_shapes(r.shape[:-2], p.shape[:-1])
    out = np.zeros(shape + (4, 4))
    out[..., :3, :3] = r
    out[..., :3, 3] = p
    out[..., 3, 3] = 1.0
    return out


def translation_pose(translation: np.ndarray) -> np.ndarray:
    """Pure translation pose (..., 4, 4) by ``translation`` (..., 3) [m]."""
    p = np.asarray(translation, dtype=float)
    return pose(np.broadcast_to(np.eye(3), p.shape[:-1] + (3, 3)), p)


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """Pose (..., 4, 4) of the twist ``xi = [rho; phi]`` (..., 6): ``R = exp(phi)``, ``p = J_l(phi) rho``."""
    xi = np.asarray(xi, dtype=float)
    rho, phi = xi[..., :3], xi[..., 3:]
    k = _coefficients(np.linalg.norm(phi, axis=-1), "abc")
    w = skew(phi)
    w2 = w @ w
    rotation = np.eye(3) + k["a"][..., None, None] * w + k["b"][..., None, None] * w2
    v = np.eye(3) + k["b"][..., None, None] * w + k["c"][..., None, None] * w2
    return pose(rotation, np.einsum("...ij,...j->...i", v, rho))


def se3_log(transform: np.ndarray) -> np.ndarray:
    """Twist (..., 6) ``[rho; phi]`` of the pose ``transform`` (..., 4, 4); inverse of ``se3_exp``."""
    t = np.asarray(transform, dtype=float)
    phi = so3_log(t[..., :3, :3])
    rho = np.einsum("...ij,...j->...i", so3_left_jacobian_inverse(phi), t[..., :3, 3])
    return np.concatenate([rho, phi], axis=-1)


def se3_inverse(transform: np.ndarray) -> np.ndarray:
    """Inverse pose (..., 4, 4): ``[[R^T, -R^T p], [0, 1]]``."""
    t = np.asarray(transform, dtype=float)
    rt = np.swapaxes(t[..., :3, :3], -1, -2)
    return pose(rt, -np.einsum("...ij,...j->...i", rt, t[..., :3, 3]))


def se3_adjoint(transform: np.ndarray) -> np.ndarray:
    """Ad(T) = [[R, [p]x R], [0, R]] (..., 6, 6) of the pose ``transform`` (..., 4, 4):
    ``T exp(xi) T^-1 = exp(Ad(T) xi)``; the ``twist_transform`` of its rotation and origin."""
    t = np.asarray(transform, dtype=float)
    return twist_transform(t[..., :3, :3], t[..., :3, 3])


def se3_ad(xi: np.ndarray) -> np.ndarray:
    """Small adjoint ad(xi) = [[[phi]x, [rho]x], [0, [phi]x]] (..., 6, 6); ``ad(a) b`` is the Lie bracket."""
    xi = np.asarray(xi, dtype=float)
    out = np.zeros(xi.shape[:-1] + (6, 6))
    wp = skew(xi[..., 3:])
    out[..., :3, :3] = wp
    out[..., 3:, 3:] = wp
    out[..., :3, 3:] = skew(xi[..., :3])
    return out


def _q_matrix(rho: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Barfoot's Q(rho, phi) (..., 3, 3), the coupling block of the SE(3) left Jacobian."""
    k = _coefficients(np.linalg.norm(phi, axis=-1), "cde")
    p, r = skew(phi), skew(rho)
    pr, rp = p @ r, r @ p
    prp = pr @ p
    c, d, e = (k[n][..., None, None] for n in "cde")
    return (0.5 * r + c * (pr + rp + prp) + d * (p @ pr + rp @ p - 3.0 * prp)
            + e * (prp @ p + p @ prp))


def se3_left_jacobian(xi: np.ndarray) -> np.ndarray:
    """SE(3) left Jacobian (..., 6, 6): ``exp(xi + d) = exp(J_l(xi) d) exp(xi)`` to first order."""
    xi = np.asarray(xi, dtype=float)
    rho, phi = xi[..., :3], xi[..., 3:]
    j = so3_left_jacobian(phi)
    out = np.zeros(xi.shape[:-1] + (6, 6))
    out[..., :3, :3] = j
    out[..., 3:, 3:] = j
    out[..., :3, 3:] = _q_matrix(rho, phi)
    return out


def se3_right_jacobian(xi: np.ndarray) -> np.ndarray:
    """SE(3) right Jacobian J_r(xi) = J_l(-xi) (..., 6, 6)."""
    return se3_left_jacobian(-np.asarray(xi, dtype=float))


def se3_left_jacobian_inverse(xi: np.ndarray) -> np.ndarray:
    """J_l(xi)^-1 = [[J^-1, -J^-1 Q J^-1], [0, J^-1]] (..., 6, 6)."""
    xi = np.asarray(xi, dtype=float)
    rho, phi = xi[..., :3], xi[..., 3:]
    j_inv = so3_left_jacobian_inverse(phi)
    out = np.zeros(xi.shape[:-1] + (6, 6))
    out[..., :3, :3] = j_inv
    out[..., 3:, 3:] = j_inv
    out[..., :3, 3:] = -j_inv @ _q_matrix(rho, phi) @ j_inv
    return out


def se3_right_jacobian_inverse(xi: np.ndarray) -> np.ndarray:
    """J_r(xi)^-1 = J_l(-xi)^-1 (..., 6, 6)."""
    return se3_left_jacobian_inverse(-np.asarray(xi, dtype=float))
