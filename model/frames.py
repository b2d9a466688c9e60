"""Chain axes for Eq. 1-3: the local frame of each chain from its end points, batched.

The rigid-body algebra (skew matrices, the 6x6 twist transform ``[[R, [r]x R], [0, R]]``,
its inverse ``frame_to_point_transform``, SE(3)) lives once in ``flexcal.geometry.frames``.
"""

from __future__ import annotations

import numpy as np

from flexcal.geometry.frames import cross

__all__ = ["axis_rotation"]


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
    return np.stack([x, y, cross(x, y)], axis=-1)
