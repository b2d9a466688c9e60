"""Small-displacement frame algebra: skew matrices, 6x6 twist/wrench transforms, chain axes.

Twists are ``[d; theta]`` (displacement [m], rotation [rad]) and wrenches ``[F; M]``
([N], [N m]), both ordered x, y, z. A twist ``t_p`` of a body expressed at point ``p`` in
a frame with axes ``R`` (columns, in the global frame) is the global twist at ``q``

    t_q = T t_p,   T = [[R, [r]x R], [0, R]],   r = p - q            (adjoint, REFERENCES.md)

and a global wrench at ``q`` acts at ``p`` in the local frame as ``T^T w_q``. The sign of
``r`` matters: ``q - p`` flips the coupling blocks. All functions are batch-first:
leading dimensions broadcast.
"""

from __future__ import annotations

import numpy as np

__all__ = ["skew", "twist_transform", "frame_to_point_transform", "axis_rotation", "rotation_about_x"]


def skew(vector: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[v]x`` with ``[v]x w = v x w``.

    vector (..., 3) -> (..., 3, 3), same unit as ``vector``.
    """
    v = np.asarray(vector, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def twist_transform(rotation: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Adjoint ``T = [[R, [r]x R], [0, R]]`` (..., 6, 6).

    rotation (..., 3, 3): columns are the local axes in the target frame; offset (..., 3) [m]:
    ``r = p - q``, the source point ``p`` minus the target point ``q`` in the target frame.
    ``T`` maps a local twist at ``p`` to the target-frame twist at ``q``; ``T^T`` maps a
    target-frame wrench at ``q`` to the local wrench at ``p``.
    """
    rot = np.asarray(rotation, dtype=float)
    r = np.asarray(offset, dtype=float)
    shape = np.broadcast_shapes(rot.shape[:-2], r.shape[:-1])
    out = np.zeros(shape + (6, 6))
    out[..., :3, :3] = rot
    out[..., 3:, 3:] = rot
    out[..., :3, 3:] = skew(r) @ rot
    return out


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (..., 3); np.cross without its per-call overhead."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def frame_to_point_transform(rotation: np.ndarray, point: np.ndarray) -> np.ndarray:
    """``J = [[R^T, -R^T [p]x], [0, R^T]]`` (..., 6, 6): a global twist at the origin
    (O_C) -> the twist of a rigidly attached point ``p`` [m] in the local frame ``R``.

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
    out[..., :3, 3:] = _cross(p[..., None, :], axes)
    return out


def axis_rotation(point_a: np.ndarray, point_b: np.ndarray, roll_reference: np.ndarray) -> np.ndarray:
    """Batched ``geometry.params.chain_rotation``: (..., 3, 3), columns = local x, y, z.

    x points from A to B ([m] inputs), y is ``roll_reference`` made orthogonal to x,
    z = x cross y. Raises ``ValueError`` if A = B or the reference is parallel to the axis.
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
    return np.stack([x, y, _cross(x, y)], axis=-1)


def rotation_about_x(angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` [rad] about x (columns = rotated axes)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
