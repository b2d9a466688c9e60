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

from . import kernel
from .chain import _dimensions, _uniform_entries, chain_elements
from .hinge import ENTRY_INDEX, segment_entries
from .serial import quarter_turn

__all__ = ["twist_bracket_tensor", "chain_defect_tensor", "chain_shortening_form", "chain_second_order_forms",
           "forms_from_elements"]


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
    transported, stiffness = _transported_elements(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                                   section=section, connector_length=connector_length,
                                                   end_block_length=end_block_length, material=material)
    return _defect(transported, stiffness), stiffness


def _transported_elements(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section,
                          connector_length, end_block_length, material) -> tuple[np.ndarray, np.ndarray]:
    """(C~_e (..., 9, 6, 6) the element compliances transported to B, K_B (..., 6, 6))."""
    compliance, rotation, points = chain_elements(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                                  section=section, connector_length=connector_length,
                                                  end_block_length=end_block_length, material=material)
    length = np.asarray(np.broadcast_to(np.asarray(length, dtype=float), points.shape[:-2]))
    offset = points - length[..., None, None] * np.array([1.0, 0.0, 0.0])
    transform = twist_transform(rotation, offset)  # (..., 9, 6, 6) element end -> B
    transported = transform @ compliance @ np.swapaxes(transform, -1, -2)
    return transported, np.linalg.inv(transported.sum(axis=-3))


def _defect(transported: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """M (..., 6, 6, 6) of ``chain_defect_tensor``."""
    gain = transported @ stiffness[..., None, :, :]  # G_e (..., 9, 6, 6)
    before = np.cumsum(gain, axis=-3) - gain  # sum_{e<f} G_e
    # q(D) = 1/2 sum_{e<f} [G_e D, G_f D]: Q[c] = 1/2 sum_f (sum_{e<f} G_e)^T A_c G_f, symmetrised
    bracket_gain = np.einsum("cpr,...frb->...fcpb", _BRACKET, gain)  # A_c G_f
    q = 0.5 * np.sum(np.swapaxes(before, -1, -2)[..., None, :, :] @ bracket_gain, axis=-4)
    q = 0.5 * (q + np.swapaxes(q, -1, -2))
    m = -q
    m[..., :3, :, :] -= 0.5 * _PHI_CROSS_D
    return m


# (e_x, 0)'s image under ad(v, w)^T is (e_x x w, e_x x v) = _AXIAL_AD (v, w): the axial force's
# moment and lateral force on a deformed element (docs: chain_load_form)
_AXIAL_AD = np.zeros((6, 6))
_AXIAL_AD[1, 5] = _AXIAL_AD[4, 2] = -1.0
_AXIAL_AD[2, 4] = _AXIAL_AD[5, 1] = 1.0


def _load_form(transported: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """T (..., 6, 6) [1/(N m), 1/N, m/N] of ``chain_second_order_forms`` from C~_e and K_B.

    The chain under its axial load N: each element carries the end wrench carried through the
    deformed chain, ``xi_e = C~_e (I + 1/2 sum_{f<e} ad_f - 1/2 sum_{f>e} ad_f)^T lambda``
    (stationarity of the elements' energy under the BCH compatibility of the module
    docstring), so with lambda = N e_x + dlambda the deformations solve
    ``eta = C~ dlambda + N A eta``, ``A_ef = 1/2 s_ef C~_e P`` (s_ef = +1 for f < e, -1 for
    f > e, P = ``_AXIAL_AD``: the axial force's moment N x offset and its lateral force
    N x rotation), with ``sum_e eta_e = D``. The end compliance is
    ``E^T (I - N A)^-1 C~ = C0 + N C1 + N^2 C2 + ...``; the stiffness's N^2 term
    ``K0 (C1 K0 C1 - C2) K0`` is T (its N term is 2 S plus the end's -1/2 phi x d, the
    shortening form: checked in the tests)."""
    n_e = transported.shape[-3]
    sign = np.sign(np.arange(n_e)[:, None] - np.arange(n_e)[None, :]).astype(float)  # s_ef = +1 for f < e
    signed = np.einsum("ef,...fab->...eab", sign, transported)  # Y_e = sum_f s_ef C~_f
    first = 0.5 * transported @ _AXIAL_AD @ signed  # Z_e = (A C~)_e
    second = 0.5 * transported @ _AXIAL_AD @ np.einsum("ef,...fab->...eab", sign, first)  # (A A C~)_e
    c1, c2 = first.sum(axis=-3), second.sum(axis=-3)
    form = stiffness @ (c1 @ stiffness @ c1 - c2) @ stiffness
    form = 0.5 * (form + np.swapaxes(form, -1, -2))
    form[..., 0, :] = 0.0
    form[..., :, 0] = 0.0
    return form


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
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S (..., 6, 6), L (..., 5, 6, 6), T (..., 6, 6)) of chains from their transported
    elements: the shortening form (``chain_shortening_form``), the load form T (the chain's
    energy gains ``1/2 N^2 D^T T D`` under its axial load N: the elements' own P-delta inside
    the chain, ``_load_form``; T < 0, the shortening ``D^T (S + N T) D`` grows under
    compression, by 0.2 % at 3 kN on the driving chains) and the lateral compatibility defect
    ``m_c(D) = D^T L[c-1] D`` 
    of components c = y, z, rx, ry, rz [m, rad] (``chain_defect_tensor``'s rows 1-5, with the
    axial direction's rows and columns zero: the end's axial displacement is microns, its
    products with D are 1e-5 of the rest). The consistent model's chain energy is
    ``1/2 e^T K e``, ``e = D - u e_x + (D^T S D, m_y, ..., m_rz)`` (docs/model.md 10): L's
    terms couple the torsion with the lateral swing (a twisted chain's leaves bend off their
    compliant axes) and give the lateral forces and moments that grow with the square of
    the stroke (on `flexcal design`'s 2-2.5 mm strokes ~1 % of the chain's lateral force).

    With numba the three run compiled on the elements' eight entries (``_numba_shortening``:
    every element is collinear with x, so the matrices are block-sparse), ~50x faster than the
    dense evaluation below, which is used without it; the two agree to rounding."""
    if kernel.available():
        return _compiled_forms(length, hinge_length, width, fillet, thickness_1, thickness_2, section=section,
                               connector_length=connector_length, end_block_length=end_block_length,
                               material=material)
    return _dense_forms(length, hinge_length, width, fillet, thickness_1, thickness_2, section=section,
                        connector_length=connector_length, end_block_length=end_block_length, material=material)


def _dense_forms(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section, connector_length,
                 end_block_length, material) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``chain_second_order_forms`` by dense (..., 9, 6, 6) matrices (numpy)."""
    transported, stiffness = _transported_elements(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                                   section=section, connector_length=connector_length,
                                                   end_block_length=end_block_length, material=material)
    m = _defect(transported, stiffness)
    lateral = m[..., 1:, :, :].copy()
    lateral[..., :, 0, :] = 0.0
    lateral[..., :, :, 0] = 0.0
    return _shortening(m, stiffness), lateral, _load_form(transported, stiffness)


def _shortening(m: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """S (..., 6, 6) from the defect tensor and K_B (module docstring)."""
    k = stiffness[..., 0, 0]
    form = k[..., None, None] * m[..., 0, :, :] + 2.0 * np.einsum("...ca,...cb->...ab", stiffness, m[..., :, 0, :])
    form = 0.5 * (form + np.swapaxes(form, -1, -2)) / k[..., None, None]
    form[..., 0, :] = 0.0
    form[..., :, 0] = 0.0
    return form


def _compiled_forms(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section, connector_length,
                    end_block_length, material) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``chain_second_order_forms`` by ``_numba_shortening.shortening_forms``."""
    entries, offsets = _element_entries(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                        section=section, connector_length=connector_length,
                                        end_block_length=end_block_length, material=material)
    return forms_from_elements(entries, offsets)


def forms_from_elements(entries: np.ndarray, offsets: np.ndarray, *, n_threads: int = 1
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``chain_second_order_forms`` (S, L, T) of chains given by their elements: entries (..., 9, 8)
    at each element's loaded end in the chain's axes (``hinge.ENTRY_INDEX`` order, leaf 2 turned),
    offsets (..., 9) [m] that end's x minus B's (``chain.chain_entries_and_elements``). Compiled
    (``_numba_shortening.shortening_forms``), the chains split over ``n_threads`` (``threads``)."""
    from . import _numba_shortening
    from .threads import run_split

    shape = offsets.shape[:-1]
    flat = np.ascontiguousarray(entries.reshape((-1,) + entries.shape[-2:]))
    n = flat.shape[0]
    flat_offsets = np.ascontiguousarray(offsets.reshape(n, -1))
    form, lateral, load = np.empty((n, 6, 6)), np.empty((n, 5, 6, 6)), np.empty((n, 6, 6))
    run_split(lambda first, stop: _numba_shortening.shortening_forms(
        flat[first:stop], flat_offsets[first:stop], _PHI_CROSS_D, _AXIAL_AD,
        form[first:stop], lateral[first:stop], load[first:stop]), n, n_threads)
    return form.reshape(shape + (6, 6)), lateral.reshape(shape + (5, 6, 6)), load.reshape(shape + (6, 6))


_KEYS = tuple(ENTRY_INDEX)  # ux_Fx, uy_Fy, uy_Mz, rz_Mz, uz_Fz, uz_My, ry_My, rx_Mx


def _element_entries(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section, connector_length,
                     end_block_length, material: Material) -> tuple[np.ndarray, np.ndarray]:
    """(entries (..., 9, 8), offsets (..., 9) [m]): the eight entries (``hinge.ENTRY_INDEX``) of
    each element of ``chain.chain_elements`` at its loaded end in the chain's axes, and that end's
    x minus B's (L). The same segments as ``chain_elements`` (leaves by ``segment_entries`` of
    their flat half and fillet; blocks, connectors and strut uniform, ``chain._uniform_entries``,
    equal to ``segment_entries`` without fillet)."""
    length, l, w, a, t1, t2, strut = _dimensions(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                                 end_block_length, connector_length)
    shape = length.shape
    section, connector, block = (np.broadcast_to(np.asarray(v, dtype=float), shape)
                                 for v in (section, connector_length, end_block_length))
    leaves = segment_entries(np.maximum(0.5 * l - a, 0.0), a, np.stack([t1, t2]), w, material.youngs_modulus,
                             material.poisson_ratio)
    leaves = np.stack([leaves[key] for key in _KEYS], axis=-1)  # (2, ..., 8)
    leaf1, leaf2 = leaves[0], np.stack(quarter_turn(np.moveaxis(leaves[1], -1, 0)), axis=-1)  # leaf 2 turned
    uniform = np.moveaxis(_uniform_entries(np.stack([block, connector, strut]), section, section, material), 0, -1)
    by_kind = {"block": uniform[0], "leaf1": leaf1, "connector": uniform[1], "leaf2": leaf2, "strut": uniform[2]}
    sizes = {"block": block, "leaf1": l, "connector": connector, "leaf2": l, "strut": strut}
    kinds = ("block", "leaf1", "connector", "leaf2", "strut", "leaf2", "connector", "leaf1", "block")
    stacked = np.stack([by_kind[k] for k in kinds], axis=-2)
    ends = np.cumsum(np.stack([sizes[k] for k in kinds], axis=-1), axis=-1)
    return stacked, ends - length[..., None]
