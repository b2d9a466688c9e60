"""SE(3) and SO(3) tools for the virtual prototype's exact kinematics.

The algebra itself (poses ``T = [[R, p], [0, 1]]``, twists ``[rho; phi]`` translation
first, exp/log, adjoints, Barfoot's Jacobians with right perturbations
``T <- T exp(delta)``) lives once in ``flexcal.geometry.frames``, shared with fem and
model; this module names what the prototype uses of it and adds the prototype's own
step, ``orthonormalize`` (its Newton updates compose many ``T exp(delta)``).
"""

from __future__ import annotations

import numpy as np

from flexcal.geometry.frames import (pose, se3_adjoint, se3_exp, se3_inverse, se3_left_jacobian_inverse, se3_log,
                                     se3_right_jacobian_inverse, so3_log, translation_pose)
from flexcal.geometry.frames import skew as hat  # Barfoot's name, as the prototype's formulas write it

__all__ = ["hat", "so3_log", "pose", "translation_pose", "se3_exp", "se3_log", "se3_inverse", "se3_adjoint",
           "se3_left_jacobian_inverse", "se3_right_jacobian_inverse", "orthonormalize"]


def orthonormalize(transform: np.ndarray) -> np.ndarray:
    """Pose (..., 4, 4) with its rotation block projected back onto SO(3) (polar decomposition).

    Removes the round-off drift that accumulates over many ``T exp(delta)`` updates.
    """
    t = np.array(transform, dtype=float)
    u, _, vt = np.linalg.svd(t[..., :3, :3])
    t[..., :3, :3] = u @ vt
    return t
