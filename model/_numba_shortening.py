"""numba kernel of ``shortening.chain_second_order_forms`` (S, L, T): the same formulas (that
module's docstrings) written on the structure of a chain whose elements are all collinear with x.

Every element compliance there has eight independent entries (``hinge.ENTRY_INDEX``: ux and rx
alone, the 2x2 blocks (uy, rz) and (uz, ry)); the transport to B (a shift along x) and the sum
and inverse keep that structure, so ``C~_e``, ``K_B`` and ``G_e = C~_e K_B`` are block matrices
with ten non-zero entries, and the bracket sum ``Q[c] = 1/2 sum_f (sum_{e<f} G_e)^T A_c G_f``
only visits the eighteen non-zero entries of the twist bracket A and each row's block. No other
approximation: the dense evaluation (``shortening._transported_elements``, ``_defect``,
``_load_form``) agrees to rounding (tests/test_shortening_fast.py). The load form T is
evaluated with 6x6 products restricted to the lateral rows and columns (``LATERAL``).
"""

import numpy as np
from numba import njit

# the files whose code or constants these cached kernels compile in, with a digest of their text
# (numba keys its cache by this file's text only: tests/test_numba_cache_keys.py)
SOURCES_COMPILED_IN = {}

_FAST = {"reassoc", "contract", "arcp"}

# the non-zero entries of the twist bracket A (``shortening.twist_bracket_tensor``, ``[a, b]_c =
# A[c, p, r] a_p b_r``) as (c, p, r, value), and each index's partner in its 2x2 block of a
# collinear chain's matrices ((uy, rz) = (1, 5), (uz, ry) = (2, 4); ux, rx alone: -1). Module
# constants, which numba compiles in: the bracket loop unrolls (session 45: 1.2x on
# ``shortening_forms`` against the same arrays as arguments, the same bits; tests check them
# against the tensor)
BRACKET_C = np.array([0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 4, 4, 5, 5], dtype=np.int64)
BRACKET_P = np.array([1, 2, 4, 5, 0, 2, 3, 5, 0, 1, 3, 4, 4, 5, 3, 5, 3, 4], dtype=np.int64)
BRACKET_R = np.array([5, 4, 2, 1, 5, 3, 2, 0, 4, 3, 1, 0, 5, 4, 5, 3, 4, 3], dtype=np.int64)
BRACKET_VALUE = np.array([1., -1., 1., -1., -1., 1., -1., 1., 1., -1., 1., -1., 1., -1., -1., 1., 1., -1.])
PARTNER = np.array([-1, 5, 4, -1, 2, 1], dtype=np.int64)


# this helper and the load form's are inlined into ``shortening_forms`` (``inline="always"``): as
# calls, their array arguments cost ~138 reference-count pairs per chain, ~28 % of its time
# (session 43: 3.6 -> 2.6 ms for 300 candidates' 1800 chains on one thread, the same bits)
@njit(cache=True, nogil=True, inline="always")
def _gain(t, k, out):
    """G = C~ K_B (6, 6) in place, from C~'s eight entries t and the dense block matrix K_B."""
    for a in range(6):
        for b in range(6):
            out[a, b] = 0.0
    out[0, 0] = t[0] * k[0, 0]
    out[3, 3] = t[7] * k[3, 3]
    out[1, 1] = t[1] * k[1, 1] + t[2] * k[5, 1]
    out[1, 5] = t[1] * k[1, 5] + t[2] * k[5, 5]
    out[5, 1] = t[2] * k[1, 1] + t[3] * k[5, 1]
    out[5, 5] = t[2] * k[1, 5] + t[3] * k[5, 5]
    out[2, 2] = t[4] * k[2, 2] + t[5] * k[4, 2]
    out[2, 4] = t[4] * k[2, 4] + t[5] * k[4, 4]
    out[4, 2] = t[5] * k[2, 2] + t[6] * k[4, 2]
    out[4, 4] = t[5] * k[2, 4] + t[6] * k[4, 4]


@njit(cache=True, nogil=True, fastmath=_FAST)
def shortening_forms(entries, offsets, phi_cross_d, axial_ad, form_out, lateral_out, load_out):
    """entries (n, 9, 8) of each element's compliance at its loaded end (chain axes, leaf 2
    turned), offsets (n, 9) [m] its loaded end minus B along x; phi_cross_d (3, 6, 6); axial_ad
    (6, 6) ``shortening._AXIAL_AD`` (the twist bracket: ``BRACKET_*``, ``PARTNER``). Writes S (n, 6, 6),
    L (n, 5, 6, 6) and T (n, 6, 6); the chain's stiffness at B, K_B, is a local (session 45: as an
    output nobody read, its fresh pages cost ~0.5 MB of page faults a call for 300 candidates).
    One thread: a few us per chain, less than starting numba's threads on a busy machine."""
    n = entries.shape[0]
    n_e = entries.shape[1]
    moved = np.zeros((n_e, 8))  # C~_e entries
    total = np.zeros(8)
    gain = np.zeros((6, 6))
    before = np.zeros((6, 6))  # sum_{e<f} G_e
    q = np.zeros((6, 6, 6))
    dense = np.zeros((n_e, 6, 6))  # C~_e
    signed = np.zeros((n_e, 6, 6))  # Y_e, then sum_f s_ef Z_f
    first = np.zeros((n_e, 6, 6))  # Z_e
    prefix = np.zeros((6, 6))
    whole = np.zeros((6, 6))
    tmp = np.zeros((6, 6))
    c1 = np.zeros((6, 6))
    c2 = np.zeros((6, 6))
    k_b = np.zeros((6, 6))  # K_B of the chain at hand
    for i in range(n):
        total[:] = 0.0
        before[:, :] = 0.0
        q[:, :, :] = 0.0
        for e in range(n_e):
            p = entries[i, e]
            d = offsets[i, e]
            t = moved[e]
            t[0] = p[0]
            t[1] = p[1] - 2.0 * d * p[2] + d * d * p[3]  # uy' = uy - d rz
            t[2] = p[2] - d * p[3]
            t[3] = p[3]
            t[4] = p[4] + 2.0 * d * p[5] + d * d * p[6]  # uz' = uz + d ry
            t[5] = p[5] + d * p[6]
            t[6] = p[6]
            t[7] = p[7]
            for k in range(8):
                total[k] += t[k]
        for a in range(6):
            for b in range(6):
                k_b[a, b] = 0.0
        k_b[0, 0] = 1.0 / total[0]
        k_b[3, 3] = 1.0 / total[7]
        det = total[1] * total[3] - total[2] * total[2]
        k_b[1, 1] = total[3] / det
        k_b[5, 5] = total[1] / det
        k_b[1, 5] = k_b[5, 1] = -total[2] / det
        det = total[4] * total[6] - total[5] * total[5]
        k_b[2, 2] = total[6] / det
        k_b[4, 4] = total[4] / det
        k_b[2, 4] = k_b[4, 2] = -total[5] / det
        for f in range(n_e):
            _gain(moved[f], k_b, gain)
            for z in range(BRACKET_C.shape[0]):
                c, p, r, v = BRACKET_C[z], BRACKET_P[z], BRACKET_R[z], 0.5 * BRACKET_VALUE[z]
                for s in range(2):
                    col_p = p if s == 0 else PARTNER[p]
                    if col_p < 0:
                        continue
                    left = v * before[p, col_p]
                    for s2 in range(2):
                        col_r = r if s2 == 0 else PARTNER[r]
                        if col_r < 0:
                            continue
                        q[c, col_p, col_r] += left * gain[r, col_r]
            for a in range(6):
                for b in range(6):
                    before[a, b] += gain[a, b]
        # m = -sym(q) - 1/2 (phi x d) rows; S = sym(k m[0] + 2 K_B^T m[:, 0, :]) / k, axial row/column zero
        k = k_b[0, 0]
        form = form_out[i]
        for a in range(6):
            for b in range(6):
                acc = 0.0
                for c in range(6):
                    m_c0b = -0.5 * (q[c, 0, b] + q[c, b, 0]) - (0.5 * phi_cross_d[c, 0, b] if c < 3 else 0.0)
                    acc += k_b[c, a] * m_c0b
                m_0ab = -0.5 * (q[0, a, b] + q[0, b, a]) - 0.5 * phi_cross_d[0, a, b]
                form[a, b] = k * m_0ab + 2.0 * acc
        for a in range(6):
            for b in range(a, 6):
                s_ab = 0.5 * (form[a, b] + form[b, a]) / k
                form[a, b] = s_ab
                form[b, a] = s_ab
        for a in range(6):
            form[0, a] = 0.0
            form[a, 0] = 0.0
        # L: rows y..rz of m = -sym(q) - 1/2 (phi x d), the axial direction's rows and columns zero
        for c in range(1, 6):
            for a in range(6):
                for b in range(6):
                    value = 0.0
                    if a > 0 and b > 0:
                        value = -0.5 * (q[c, a, b] + q[c, b, a]) - (0.5 * phi_cross_d[c, a, b] if c < 3 else 0.0)
                    lateral_out[i, c - 1, a, b] = value
        _load_form(moved, k_b, axial_ad, dense, signed, first, prefix, whole, tmp, c1, c2, load_out[i])


# the lateral indices (uy, uz, ry, rz): C~_e and K_B are block matrices on (ux), (rx), (uy, rz) and
# (uz, ry), and P = ``shortening._AXIAL_AD`` maps the two lateral blocks into each other, so C~_e P,
# Z_e, C1, C2 and T live on the lateral rows and columns only; the load form's products visit those
# (16 of 36 entries, 64 of 216 terms per 6x6 product; session 19, ~2.5x less work, the same terms)
LATERAL = np.array([1, 2, 4, 5], dtype=np.int64)


@njit(cache=True, nogil=True, inline="always")
def _signed_sum(parts, out, prefix, whole):
    """out_e = sum_f sign(e - f) parts_f = 2 sum_{f<e} parts_f - sum_f parts_f + parts_e, on the
    lateral rows and columns (``LATERAL``; the rest of out is left as it was)."""
    n_e = parts.shape[0]
    for ia in range(4):
        a = LATERAL[ia]
        for ib in range(4):
            b = LATERAL[ib]
            acc = 0.0
            for e in range(n_e):
                acc += parts[e, a, b]
            whole[a, b] = acc
            prefix[a, b] = 0.0
    for e in range(n_e):
        for ia in range(4):
            a = LATERAL[ia]
            for ib in range(4):
                b = LATERAL[ib]
                out[e, a, b] = 2.0 * prefix[a, b] - whole[a, b] + parts[e, a, b]
                prefix[a, b] += parts[e, a, b]


@njit(cache=True, nogil=True, inline="always")
def _half_ad_product(left, axial_ad, right, out):
    """out = 1/2 left P right on the lateral rows and columns (``LATERAL``; the rest of out is left
    as it was) for P = ``shortening._AXIAL_AD``: P[1, 5] = P[4, 2] = -1, P[2, 4] = P[5, 1] = 1 (its
    only non-zero entries; checked by the caller's tests)."""
    for ia in range(4):
        a = LATERAL[ia]
        l1, l2, l4, l5 = left[a, 1], left[a, 2], left[a, 4], left[a, 5]
        for ib in range(4):
            b = LATERAL[ib]
            out[a, b] = 0.5 * (-l1 * right[5, b] - l4 * right[2, b] + l2 * right[4, b] + l5 * right[1, b])


@njit(cache=True, nogil=True, inline="always")
def _product(left, right, out):
    """out = left right on the lateral rows and columns, over the lateral inner index (``LATERAL``:
    exact where left's lateral rows are zero off them; the rest of out is left as it was)."""
    for ia in range(4):
        a = LATERAL[ia]
        for ib in range(4):
            b = LATERAL[ib]
            acc = 0.0
            for ik in range(4):
                k = LATERAL[ik]
                acc += left[a, k] * right[k, b]
            out[a, b] = acc


@njit(cache=True, nogil=True, inline="always")
def _load_form(moved, k_b, axial_ad, dense, signed, first, prefix, whole, tmp, c1, c2, out):
    """T (6, 6) of ``shortening._load_form``: Y_e = sum_f s_ef C~_f, Z_e = 1/2 C~_e P Y_e,
    C1 = sum Z_e, C2 = sum 1/2 C~_e P (sum_f s_ef Z_f), T = sym(K (C1 K C1 - C2) K), axial zero;
    every factor on the lateral rows and columns (``LATERAL``), T zero off them."""
    n_e = moved.shape[0]
    for e in range(n_e):
        t = moved[e]
        d = dense[e]
        d[:, :] = 0.0
        d[0, 0] = t[0]
        d[1, 1], d[1, 5], d[5, 1], d[5, 5] = t[1], t[2], t[2], t[3]
        d[2, 2], d[2, 4], d[4, 2], d[4, 4] = t[4], t[5], t[5], t[6]
        d[3, 3] = t[7]
    _signed_sum(dense, signed, prefix, whole)
    c1[:, :] = 0.0
    for e in range(n_e):
        _half_ad_product(dense[e], axial_ad, signed[e], first[e])
        for ia in range(4):
            a = LATERAL[ia]
            for ib in range(4):
                b = LATERAL[ib]
                c1[a, b] += first[e, a, b]
    _signed_sum(first, signed, prefix, whole)
    c2[:, :] = 0.0
    for e in range(n_e):
        _half_ad_product(dense[e], axial_ad, signed[e], tmp)
        for ia in range(4):
            a = LATERAL[ia]
            for ib in range(4):
                b = LATERAL[ib]
                c2[a, b] += tmp[a, b]
    # K (C1 K C1 - C2) K
    _product(c1, k_b, tmp)
    _product(tmp, c1, prefix)
    for ia in range(4):
        a = LATERAL[ia]
        for ib in range(4):
            b = LATERAL[ib]
            prefix[a, b] -= c2[a, b]
    _product(k_b, prefix, tmp)
    out[:, :] = 0.0
    _product(tmp, k_b, out)
    for ia in range(4):
        a = LATERAL[ia]
        for ib in range(ia, 4):
            b = LATERAL[ib]
            value = 0.5 * (out[a, b] + out[b, a])
            out[a, b] = value
            out[b, a] = value
