"""Geometrically exact segment superelements (co-rotational, relative-pose form).

A segment joins a start node i and an end node j, each carrying a full pose
``T = (R, p)`` (4 x 4, ``flexcal.validation.prototype.kinematics``). Its deformation is the
body-frame twist

    xi = log( D T_i^-1 T_j ),     D = (T_i0^-1 T_j0)^-1                      (1)

the pose of the end node relative to where the start node would carry it rigidly,
expressed in that undeformed end frame (subscript 0: undeformed). Its energy is

    U = 1/2 xi^T K_jj xi                                                      (2)

with ``K_jj`` (6 x 6) the end-node block of the segment's 12 x 12 stiffness (start
clamped, at the end node, segment frame). ``xi`` vanishes for every rigid motion of the
segment, however large, so rigid rotations never make strain energy; for small node
motions ``xi = u_j - Ad(D) u_i`` and (2) is the linear 12 x 12 stiffness exactly.

Node perturbations are on the right, ``T <- T exp(delta)`` (body frame). Differentiating
(1) (kinematics module docstring):

    d xi / d delta_j = J_r(xi)^-1,      d xi / d delta_i = -J_l(xi)^-1 Ad(D)

so the generalized forces (energy gradient; minus the forces on the nodes) are

    g_j = J_r(xi)^-T K xi,              g_i = -Ad(D)^T J_l(xi)^-T K xi        (3)

(forces [N] then moments [N m], node body frames). The tangent is the Hessian of the
pulled-back energy ``U(T_i exp(d_i), T_j exp(d_j))`` at d = 0, obtained as the
symmetrized central difference of (3): differencing the manifold gradient along
``exp(+-h e_b)`` gives that Hessian plus a part antisymmetric in (a, b)
(``g . [e_a, e_b] / 2``, from J_r(h e_b) = I - ad(h e_b)/2), which symmetrizing removes;
the difference error is O(h^2) (~1e-10 relative for h = 1e-6 on segments of >= 1 cm).
It contains the geometric stiffness (axial load x rotation) that Newton needs to
converge quadratically on a preloaded mechanism.

All functions take batches of segments: relative poses (..., 4, 4), stiffness (..., 6, 6).
"""

from __future__ import annotations

import numpy as np

from .kinematics import (se3_adjoint, se3_exp, se3_inverse, se3_left_jacobian_inverse, se3_log, se3_right_jacobian_inverse)

__all__ = [
    "relative_pose",
    "segment_deformation",
    "segment_energy",
    "segment_gradient",
    "segment_tangent",
    "DEFAULT_STEP",
]

# Central-difference step of the tangent: 1e-6 m for translations and 1e-6 rad for
# rotations. The truncation error is ~(h / segment length)^2 < 1e-8 relative; the
# round-off error of a gradient difference is ~K * 1e-16 m / h, ~1e-9 relative.
DEFAULT_STEP = 1e-6


def relative_pose(start_pose: np.ndarray, end_pose: np.ndarray) -> np.ndarray:
    """``T_i^-1 T_j`` (..., 4, 4): the end node's pose in the start node's frame."""
    return se3_inverse(start_pose) @ end_pose


def segment_deformation(relative: np.ndarray, reference_inverse: np.ndarray) -> np.ndarray:
    """Deformation twist xi (..., 6) [m, rad] of Eq. (1) from ``T_i^-1 T_j`` and ``D`` (..., 4, 4)."""
    return se3_log(reference_inverse @ relative)


def segment_energy(relative: np.ndarray, reference_inverse: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """Strain energy (...,) [J] of Eq. (2); ``stiffness`` K_jj (..., 6, 6) [SI]."""
    xi = segment_deformation(relative, reference_inverse)
    return 0.5 * np.einsum("...i,...ij,...j->...", xi, stiffness, xi)


def segment_gradient(relative: np.ndarray, reference_inverse: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """Energy gradient ``[g_i; g_j]`` (..., 12) of Eq. (3) [N, N m], node body frames."""
    xi = segment_deformation(relative, reference_inverse)
    wrench = np.einsum("...ij,...j->...i", stiffness, xi)  # K xi, at the end node
    g_end = np.einsum("...ji,...j->...i", se3_right_jacobian_inverse(xi), wrench)
    g_start = -np.einsum("...ji,...j->...i", se3_adjoint(reference_inverse),
                         np.einsum("...ji,...j->...i", se3_left_jacobian_inverse(xi), wrench))
    return np.concatenate([g_start, g_end], axis=-1)


def segment_tangent(relative: np.ndarray, reference_inverse: np.ndarray, stiffness: np.ndarray,
                    step: float = DEFAULT_STEP) -> np.ndarray:
    """Consistent tangent (..., 12, 12) [SI]: symmetrized central difference of the gradient.

    See the module docstring. Perturbing the start node by ``exp(d)`` maps the relative
    pose to ``exp(-d) T_ij``; perturbing the end node to ``T_ij exp(d)``.
    """
    relative = np.asarray(relative, dtype=float)
    steps = step * np.eye(6)
    plus, minus = se3_exp(steps), se3_exp(-steps)  # (6, 4, 4)
    rel = relative[..., None, :, :]
    perturbed = np.concatenate([
        minus @ rel, plus @ rel,  # start node +h, -h
        rel @ plus, rel @ minus,  # end node +h, -h
    ], axis=-3)  # (..., 24, 4, 4)
    grads = segment_gradient(perturbed, reference_inverse[..., None, :, :], stiffness[..., None, :, :])
    columns = np.concatenate([grads[..., 0:6, :] - grads[..., 6:12, :],
                              grads[..., 12:18, :] - grads[..., 18:24, :]], axis=-2) / (2.0 * step)
    tangent = np.swapaxes(columns, -1, -2)  # column b = derivative along DOF b
    return 0.5 * (tangent + np.swapaxes(tangent, -1, -2))
