"""A chain's second-order shortening from its own elements: the flexible chain with exact
rigid-body kinematics at its element joints (docs/model.md 10).

The chain (``chain.chain_elements``: block, leaf 1, connector, leaf 2, strut, ... from A to B)
is a series of elastic elements; element e deforms by a twist xi_e (at its loaded end, its own
axes) with the energy ``1/2 xi_e^T C_e^-1 xi_e`` (closed-form C_e, Eq. 1's elements), and the
node poses compose exactly: ``T_B = prod_e P_e exp(xi_e)`` (P_e the element's undeformed
length along x). Transported to B, ``eta_e = T_e xi_e`` (Eq. 1's adjoint) and by the
Baker-Campbell-Hausdorff formula

    log(T_B0^-1 T_B) = sum_e eta_e + 1/2 sum_{e<f} [eta_e, eta_f] + O(3),

with ``[a, b] = (w_a x v_b - w_b x v_a, w_a x w_b)`` for twists (v, w). The end B is moved
by D = (d, phi) (translation of B, rotation vector; chain frame, A clamped), so
``log(T_B0^-1 T_B) = (d - 1/2 phi x d, phi) + O(3)``. With A clamped, the first-order
deformations are ``eta_e = G_e D``, ``G_e = C~_e K_B`` (C~_e = T_e C_e T_e^T, K_B = (sum C~_e)^-1),
and the energy to third order is ``1/2 D^T K_B D + (K_B D)^T m(D)`` with the quadratic
compatibility defect ``m(D) = (-1/2 phi x d, 0) - 1/2 sum_{e<f} [G_e D, G_f D]`` (the
interior distribution is stationary, so its second-order change does not enter). The axial
force ``N = dU/dd_x = k (D_x + D^T S D) + O(D^3)`` then gives

    S = sym(k M_x + 2 K_B^T M[:, x, :]) / k     (M the symmetric bilinear tensor of m),

rows and columns of the axial direction zero (it has no second-order shortening). This is
Eq. 4-5's parasitic shortening without the pivot idealisation: where the leaves bend, how
much the blocks and the strut give, and the couplings of translation and rotation all come
from the element compliances, so S follows the chain's dimensions.
"""

from __future__ import annotations

import numpy as np

from flexcal.geometry.frames import twist_transform
from flexcal.geometry.params import Material

from .chain import chain_elements

__all__ = ["twist_bracket_tensor", "chain_defect_tensor", "chain_shortening_form", "chain_second_order_forms"]


def _levi_civita() -> np.ndarray:
    eps = np.zeros((3, 3, 3))
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        eps[i, j, k], eps[i, k, j] = 1.0, -1.0
    return eps


def twist_bracket_tensor() -> np.ndarray:
    """A (6, 6, 6): ``[a, b]_c = A[c, p, r] a_p b_r`` for twists (v, w) (module docstring)."""
    eps = _levi_civita()
    out = np.zeros((6, 6, 6))
    out[:3, 3:, :3] += eps  # w_a x v_b
    out[:3, :3, 3:] -= np.swapaxes(eps, 1, 2)  # - w_b x v_a
    out[3:, 3:, 3:] = eps  # w_a x w_b
    return out


def _rotation_cross_translation() -> np.ndarray:
    """P (3, 6, 6) symmetric in its last two axes: ``(phi x d)_c = D^T P[c] D`` for D = (d, phi)."""
    eps = _levi_civita()
    out = np.zeros((3, 6, 6))
    out[:, 3:, :3] = 0.5 * eps
    out[:, :3, 3:] = 0.5 * np.swapaxes(eps, 1, 2)
    return out


_BRACKET = twist_bracket_tensor()
_PHI_CROSS_D = _rotation_cross_translation()


def chain_defect_tensor(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section: float,
                        connector_length: float, end_block_length: float, material: Material
                        ) -> tuple[np.ndarray, np.ndarray]:
    """(M (..., 6, 6, 6), K_B (..., 6, 6)): the quadratic compatibility defect
    ``m_c(D) = D^T M[c] D`` of the chain's end (module docstring; M symmetric in its last two
    axes) and the chain stiffness at B (chain frame, A clamped, no actuator). Dimensions as in
    ``chain.chain_elements`` (batch-broadcast, [m])."""
    compliance, rotation, points = chain_elements(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                                  section=section, connector_length=connector_length,
                                                  end_block_length=end_block_length, material=material)
    length = np.asarray(np.broadcast_to(np.asarray(length, dtype=float), points.shape[:-2]))
    offset = points - length[..., None, None] * np.array([1.0, 0.0, 0.0])
    transform = twist_transform(rotation, offset)  # (..., 9, 6, 6) element end -> B
    transported = transform @ compliance @ np.swapaxes(transform, -1, -2)
    stiffness = np.linalg.inv(transported.sum(axis=-3))  # K_B (..., 6, 6)
    gain = transported @ stiffness[..., None, :, :]  # G_e (..., 9, 6, 6)
    before = np.cumsum(gain, axis=-3) - gain  # sum_{e<f} G_e
    # q(D) = 1/2 sum_{e<f} [G_e D, G_f D]: Q[c] = 1/2 sum_f (sum_{e<f} G_e)^T A_c G_f, symmetrised
    bracket_gain = np.einsum("cpr,...frb->...fcpb", _BRACKET, gain)  # A_c G_f
    q = 0.5 * np.sum(np.swapaxes(before, -1, -2)[..., None, :, :] @ bracket_gain, axis=-4)
    q = 0.5 * (q + np.swapaxes(q, -1, -2))
    m = -q
    m[..., :3, :, :] -= 0.5 * _PHI_CROSS_D
    return m, stiffness


def chain_shortening_form(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section: float,
                          connector_length: float, end_block_length: float, material: Material) -> np.ndarray:
    """S (..., 6, 6) [1/m, 1, m] of chains (module docstring): ``N = k (D_x + D^T S D)`` for an end
    displacement D (chain frame at B, A clamped, no actuator). Dimensions as in
    ``chain.chain_elements`` (batch-broadcast, [m])."""
    return chain_second_order_forms(length, hinge_length, width, fillet, thickness_1, thickness_2, section=section,
                                    connector_length=connector_length, end_block_length=end_block_length,
                                    material=material)[0]


def chain_second_order_forms(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section: float,
                             connector_length: float, end_block_length: float, material: Material
                             ) -> tuple[np.ndarray, np.ndarray]:
    """(S (..., 6, 6), L (..., 5, 6, 6)) of chains from one defect tensor: the shortening form
    (``chain_shortening_form``) and the lateral compatibility defect ``m_c(D) = D^T L[c-1] D``
    of components c = y, z, rx, ry, rz [m, rad] (``chain_defect_tensor``'s rows 1-5, with the
    axial direction's rows and columns zero: the end's axial displacement is microns, its
    products with D are 1e-5 of the rest). The consistent model's chain energy is
    ``1/2 e^T K e``, ``e = D - u e_x + (D^T S D, m_y, ..., m_rz)`` (docs/model.md 10): L's
    terms couple the torsion with the lateral swing (a twisted chain's leaves bend off their
    compliant axes) and give the lateral forces and moments that grow with the square of
    the stroke (on `flexcal design`'s 2-2.5 mm strokes ~1 % of the chain's lateral force)."""
    m, stiffness = chain_defect_tensor(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                       section=section, connector_length=connector_length,
                                       end_block_length=end_block_length, material=material)
    lateral = m[..., 1:, :, :].copy()
    lateral[..., :, 0, :] = 0.0
    lateral[..., :, :, 0] = 0.0
    return _shortening(m, stiffness), lateral


def _shortening(m: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """S (..., 6, 6) from the defect tensor and K_B (module docstring)."""
    k = stiffness[..., 0, 0]
    form = k[..., None, None] * m[..., 0, :, :] + 2.0 * np.einsum("...ca,...cb->...ab", stiffness, m[..., :, 0, :])
    form = 0.5 * (form + np.swapaxes(form, -1, -2)) / k[..., None, None]
    form[..., 0, :] = 0.0
    form[..., :, 0] = 0.0
    return form
