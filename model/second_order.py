"""Second-order geometric terms the paper's linear kinetostatics leaves out (docs/model.md 8).

Two effects of the finite rotations (a few mrad) and of the large chain preloads (the
payload's weight, ~kN), each of second order in the frame's displacement, found by
comparing the model with the virtual prototype's exact kinematics:

1. **P-delta of the chain forces.** A chain carrying an axial load N swings sideways with
   the frame; its force then tilts by the swing over its pivot distance L_d and pushes the
   frame sideways: a geometric stiffness ``K_G = sum_i N_i P_i^T P_i / L_d,i`` with P_i the
   chain's two scaled pivot rows of Eq. 4-5 (``MechanismMatrices.parasitic_rows``), the same
   rows whose quadratic form gives the parasitic shortening. The part from the weight's
   preload enters the frame stiffness once per candidate (``model.assembly``); the part
   from the load changes along the trajectory is the per-point correction here.
2. **Rigid second-order kinematics of the frame.** A chain end at p moves by
   ``theta x p + 1/2 theta x (theta x p)`` under the rotation vector theta, not by the
   linear term alone; the second-order part strains the chains.

``second_order_pose`` applies both as one Newton step from the linear solution,
``X = X_1 - K_T^-1 f(X_1)``, with f the residual force of the two terms at X_1 and K_T the
frame stiffness (preload P-delta included): the remaining error is of third order.
"""

from __future__ import annotations

import numpy as np

__all__ = ["preload_geometric_stiffness", "second_order_pose"]


def preload_geometric_stiffness(loads: np.ndarray, parasitic_rows: np.ndarray,
                                pivot_distance: np.ndarray) -> np.ndarray:
    """``K_G = sum_i N_i P_i^T P_i / L_d,i`` (..., 6, 6) [N/m, N, N m].

    loads (..., 6) [N] chain axial loads (tension positive: stiffening); parasitic_rows
    (..., 12, 6) as in ``MechanismMatrices`` (y rows of the six chains, then z rows);
    pivot_distance L_d (..., 6) [m].
    """
    rows = np.asarray(parasitic_rows, float)
    per_chain = rows.reshape(rows.shape[:-2] + (2, 6, 6))  # (..., y/z, chain, dof)
    weight = np.asarray(loads, float) / np.asarray(pivot_distance, float)
    return np.einsum("...j,...qjd,...qje->...de", weight, per_chain, per_chain)


def second_order_pose(matrices, pose: np.ndarray, loads: np.ndarray) -> np.ndarray:
    """The pose (n_c, n_p, 6) [m, rad] corrected by one Newton step for the load-change
    P-delta and the rigid second-order frame kinematics.

    matrices: ``MechanismMatrices`` (their frame stiffness already holds the preload
    P-delta when built with ``ParameterSpace.second_order``); pose: the linear solution
    (n_c, n_p, 6); loads (n_c, n_p, 6) [N] the chain axial loads there.
    """
    m = matrices
    pose = np.asarray(pose, float)
    n_c, n_p = pose.shape[:2]
    pivot = 0.5 / m.parasitic_coefficient  # L_d (n_c, 6) [m]
    weight = (np.asarray(loads, float) - m.gravity_loads[:, None, :]) / pivot[:, None, :]  # (n_c, n_p, 6)
    rows = m.parasitic_rows  # (n_c, 12, 6): y rows of the six chains, then z rows
    swing = pose @ np.swapaxes(rows, 1, 2)  # pivot swings (n_c, n_p, 12)
    force = (swing * np.concatenate([weight, weight], axis=-1)) @ rows  # (n_c, n_p, 6)
    # rigid second order: the chain ends' extra displacement 1/2 theta x (theta x p) =
    # 1/2 (theta (theta . p) - p |theta|^2) [m] (world axes), as the frame wrench it causes,
    # sum_j J_j^T K_j [R_j^T e_j; 0] = 1/2 (theta^T Q theta - |theta|^2 W p) with the
    # per-candidate Q_a = sum_j W_j,a p_j^T and W p = sum_j W_j p_j (no per-point cross products)
    theta = pose[..., 3:]
    to_wrench = np.einsum("cjba,cjbk,cjlk->cjal", m.frame_transform, m.chain_stiffness[..., :3], m.rotation,
                          optimize=True)  # (n_c, 6 chains, 6, 3)
    quadratic = np.einsum("cjal,cjk->calk", to_wrench, m.point_b, optimize=True).reshape(n_c, 18, 3)
    linear = np.einsum("cjal,cjl->ca", to_wrench, m.point_b, optimize=True)  # (n_c, 6)
    q_theta = (theta @ np.swapaxes(quadratic, 1, 2)).reshape(n_c, n_p, 6, 3)  # Q_a theta (n_c, n_p, 6, 3)
    force += 0.5 * (np.sum(q_theta * theta[:, :, None, :], axis=-1)
                    - np.sum(theta * theta, axis=-1)[..., None] * linear[:, None, :])
    compliance = np.linalg.inv(m.frame_stiffness)
    return pose - force @ np.swapaxes(compliance, 1, 2)
