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

**Coupled segments** (``CoupledStiffness``; docs/meshing.md, "Session 24: the tied-cut
frame"). A group of m segments joined through section fields carries one stiffness K
(6 m x 6 m) on their twists Xi = (xi_1, ..., xi_m): energy 1/2 Xi^T K Xi. Segment s's
generalized forces are (3) with K xi replaced by its share of the group's wrench,
w_s = (K Xi)_s = K_ss xi_s + c_s, c_s = sum_(t != s) K_st xi_t (``wrench_offset``). The
tangent's block of segment s with itself is the symmetrized central difference of (3) with
c_s held fixed (that contains the geometric terms of J(xi_s) and J_s^T K_ss J_s); its block
with another segment t of the group is J_s^T K_st J_t exactly, J_s = d xi_s / d delta
(``segment_jacobian``, 6 x 12). With K block diagonal, c = 0 and the cross blocks vanish:
the uncoupled segments above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kinematics import (se3_adjoint, se3_exp, se3_inverse, se3_left_jacobian_inverse, se3_log, se3_right_jacobian_inverse)

__all__ = [
    "relative_pose",
    "segment_deformation",
    "segment_energy",
    "segment_gradient",
    "segment_tangent",
    "segment_jacobian",
    "CoupledStiffness",
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


def segment_gradient(relative: np.ndarray, reference_inverse: np.ndarray, stiffness: np.ndarray,
                     wrench_offset: np.ndarray | None = None, deformation: np.ndarray | None = None) -> np.ndarray:
    """Energy gradient ``[g_i; g_j]`` (..., 12) of Eq. (3) [N, N m], node body frames.
    wrench_offset (..., 6) [N, N m]: c added to K xi (a coupled segment's share of its group's
    wrench from the other segments, module docstring); None: none. deformation: xi (...,
    6) if the caller has it (``segment_deformation`` of the same poses), else computed here."""
    xi = segment_deformation(relative, reference_inverse) if deformation is None else deformation
    wrench = np.einsum("...ij,...j->...i", stiffness, xi)  # K xi, at the end node
    if wrench_offset is not None:
        wrench = wrench + wrench_offset
    g_end = np.einsum("...ji,...j->...i", se3_right_jacobian_inverse(xi), wrench)
    g_start = -np.einsum("...ji,...j->...i", se3_adjoint(reference_inverse),
                         np.einsum("...ji,...j->...i", se3_left_jacobian_inverse(xi), wrench))
    return np.concatenate([g_start, g_end], axis=-1)


def segment_tangent(relative: np.ndarray, reference_inverse: np.ndarray, stiffness: np.ndarray,
                    step: float = DEFAULT_STEP, wrench_offset: np.ndarray | None = None) -> np.ndarray:
    """Consistent tangent (..., 12, 12) [SI]: symmetrized central difference of the gradient
    (``wrench_offset`` (..., 6) held fixed, as ``segment_gradient``'s).

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
    offset = None if wrench_offset is None else np.asarray(wrench_offset)[..., None, :]
    grads = segment_gradient(perturbed, reference_inverse[..., None, :, :], stiffness[..., None, :, :], offset)
    columns = np.concatenate([grads[..., 0:6, :] - grads[..., 6:12, :],
                              grads[..., 12:18, :] - grads[..., 18:24, :]], axis=-2) / (2.0 * step)
    tangent = np.swapaxes(columns, -1, -2)  # column b = derivative along DOF b
    return 0.5 * (tangent + np.swapaxes(tangent, -1, -2))


def segment_jacobian(relative: np.ndarray, reference_inverse: np.ndarray) -> np.ndarray:
    """J = d xi / d [delta_i; delta_j] (..., 6, 12) [1 or 1/m, m or 1]: ``[-J_l(xi)^-1 Ad(D),
    J_r(xi)^-1]`` (module docstring), node body frames."""
    xi = segment_deformation(relative, reference_inverse)
    start = -se3_left_jacobian_inverse(xi) @ se3_adjoint(reference_inverse)
    return np.concatenate([start, se3_right_jacobian_inverse(xi)], axis=-1)


@dataclass(frozen=True, kw_only=True, eq=False)
class CoupledStiffness:
    """Groups of segments that share one stiffness on their twists (module docstring).

    blocks (n_groups, 6 m, 6 m) [SI]: each group's K, symmetric, on (xi_1, ..., xi_m) of its
    segments in the order of ``segments`` (n_groups, m) int, the segments' indices (each
    segment of the assembly in exactly one group).
    """

    blocks: np.ndarray
    segments: np.ndarray

    def __post_init__(self) -> None:
        blocks = np.asarray(self.blocks, dtype=float)
        segments = np.asarray(self.segments, dtype=np.int64)
        if segments.ndim != 2 or blocks.shape != (segments.shape[0], 6 * segments.shape[1], 6 * segments.shape[1]):
            raise ValueError(f"blocks {blocks.shape} must be (n_groups, 6 m, 6 m) for segments {segments.shape} "
                             "(n_groups, m)")
        if len(np.unique(segments)) != segments.size:
            raise ValueError("a segment may belong to one group only")
        object.__setattr__(self, "blocks", blocks)
        object.__setattr__(self, "segments", segments)

    @property
    def n_segments(self) -> int:
        return int(self.segments.size)

    def diagonal(self) -> np.ndarray:
        """(n_segments, 6, 6): each segment's own block K_ss, by segment index."""
        n_groups, m = self.segments.shape
        blocks = self.blocks.reshape(n_groups, m, 6, m, 6)
        out = np.zeros((self.n_segments, 6, 6))
        out[self.segments] = blocks[:, np.arange(m), :, np.arange(m), :].transpose(1, 0, 2, 3)
        return out

    def wrench(self, xi: np.ndarray) -> np.ndarray:
        """(n_segments, 6) [N, N m]: (K Xi)_s of each segment from the twists ``xi`` (n_segments, 6)."""
        grouped = xi[self.segments].reshape(self.segments.shape[0], -1)
        out = np.zeros((self.n_segments, 6))
        out[self.segments] = np.einsum("gab,gb->ga", self.blocks, grouped).reshape(self.segments.shape + (6,))
        return out
