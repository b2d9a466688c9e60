"""numba kernel of ``consistent.py``: the per-point equilibrium with the chains' second-order
shortening, the P-delta, their lateral compatibility defect and load form (``_terms``), the
rigid second-order frame kinematics and the turning lever arms of the chain forces, and the
clearance (with its play state) by Newton steps on the nut offsets. See ``consistent.py``.

Per point: the pose X is the fixed point of ``X = K^-1 (F_C + sum_j g_j u_j - f2(X))`` at given
nut offsets C (``_equilibrium``, contracts by ~1e-2 per step); the offsets solve Eq. 6-7,
``C = clip(play(C_prev, mu rho, band / k), 0, CL)``, with the release ``rho = C + N_D / k`` and
``k_i = -dN_i/dC_i`` the nut's stiffness at this equilibrium (the mechanism re-equilibrating;
the linear model's Schur complement s_i misses the second-order load change, 2-5 % here, which
the nut amplifies by mu / (1 - mu)). Each Newton step measures dN/dC on the equilibrium itself
(one more equilibrium per nut off its flank, C_k + h), linearises rho and solves the linearised
box/play problem exactly (``solve_box`` / ``solve_play``). With the linear model's tangent (the
plain fixed point of before) the iteration locked into 2-cycles on random candidates. Where
a nut is off its flank, the first Newton step of a point runs its equilibrium and probes to
``LOOSE_TOL`` only and never ends the point: it moves C most of the way, the tight steps after
it (whose rates give the release) end it, so the results are those of tight steps throughout to
the iteration's own tolerance (session 16); that loose step takes the previous point's last tight
rates of a nut that was off its flank there too instead of probing it (session 19).
"""

import numpy as np
from numba import njit

from ._numba_kernels import solve_box, solve_play  # both inlined (``inline="always"``), as ``_equilibrium`` is
from .consistent_native import equilibrium, offsets
from .point_status import CLEARANCE_FAILED, DIVERGED, NOT_CONVERGED, OK

# the files whose code or constants these cached kernels compile in, with a digest of their text
# (numba keys its cache by this file's text only: tests/test_numba_cache_keys.py)
SOURCES_COMPILED_IN = {"_numba_kernels.py": "2caf0299d30a8c71", "point_status.py": "9ba9d4aa3a906f93",
                       "consistent_native.py": "d4b395a53158cabf"}

_FAST = {"reassoc", "contract", "arcp"}
TANGENT_STEP = 1e-6  # [m] offset step of the measured tangent: its second-order error ~1e-6 relative
MAX_NEWTON = 40  # Newton steps on the offsets per point (2-4 where a nut leaves its flank)
# the pose is iterated 100x tighter than the offsets' tolerance: near two free nuts with
# coupling ~0.9, (I - B)^-1 amplifies the pose's rounding by up to ~100 in the offsets
INNER_SHARE = 1e-2
PROBE_TOL = 1e-14  # [m, rad] a probe's pose: its rate error ~ 1e-12 / TANGENT_STEP x 1e8 N/m, 5e-5 relative
# [m, rad] the pose and probes of a point's first Newton step on the offsets where a nut is off
# its flank: that step only moves C towards the solution (its rates 1e-3 off at most), the next
# ones, at the tight tolerances, end it (session 16: 16.8 -> 15.0 evaluations per posture)
LOOSE_TOL = 1e-9
MIN_STIFFNESS = 0.2  # a measured nut stiffness below this share of the linear one is not trusted (linear used)
# the lateral defect's terms (c, a, b) of chains symmetric about their axis (``consistent.defect_terms``
# lays their coefficients out in this order when a call's chains have no others): the torsion's
# couplings and (dy, ry), (dz, rz), (ry, rz) in the torsion's own defect; (3, 1, 2) is a rounding-level
# entry (<= 4e-13). ``_terms`` writes them out as products of locals (session 21): the general loop
# over an index, kept for other chains, was ~1/4 of the kernel's time
SYMMETRIC_DEFECT = np.array([[1, 2, 3], [1, 3, 4], [2, 1, 3], [2, 3, 5], [3, 1, 2], [3, 1, 4], [3, 2, 5], [3, 4, 5],
                             [4, 1, 3], [4, 3, 5], [5, 2, 3], [5, 3, 4]], dtype=np.int64)


# pack rows (``consistent.pack_chains``): per candidate and chain one (N_PACK, WIDTH) block of
# the chain's matrices, each row padded to 8 columns (64 bytes), read by ``_terms`` as columns
# or rows of its 6x6 products (one contiguous block per chain instead of eight arrays)
WIDTH = 8
J_COL = 0  # 0-5: J[:, k] (frame twist -> chain end D)
R_ROW = 6  # 6-8: R[b, :3] (the chain frame's axes in the frame's)
S_COL = 9  # 9-14: S[:, k] (shortening form)
K_COL = 15  # 15-20: K[:, k] (chain stiffness at B)
T_COL = 21  # 21-26: T[:, k] with T's axial row and column zero (load form)
J_ROW = 27  # 27-32: J[a, :]
W_COL = 33  # 33-35: (J^T K[:, :3] R^T)[:, b] (``to_wrench``)
GAIN = 36  # axial_gain[:, j] (J^T K[:, 0])
AXIAL_ROW = 37  # K[0, :3]
K_ROW0 = 38  # K[0, :]
N_PACK = 39


@njit(inline="always", nogil=True)
def _put(out, lanes, at, j, row, col, value):
    """One entry [chain j, row, col] of a candidate's pack at ``out[at]``: out (n, 6, N_PACK, WIDTH)
    as ``pack_chains`` lays it out, or with ``lanes`` (n, N_PACK, WIDTH, 8), chain j in lane j."""
    if lanes:
        out[at, row, col, j] = value
    else:
        out[at, j, row, col] = value


@njit(cache=True, nogil=True)
def fill_pack(transform, rotation, shortening, stiffness, load_form, gain, first, stop, out, lanes, shift):
    """The pack rows above of candidates ``first`` to ``stop - 1`` into ``out[cand - shift]`` (zeros
    where no entry goes; layout by ``lanes``, see ``_put``): J's columns and rows, R, the shortening form S,
    K, the load form T with its axial row and column zero (``shortening._load_form``), J^T K[:, :3]
    R^T (``to_wrench``), the axial gain's column j and K's first row. transform, shortening,
    stiffness, load_form (n_c, 6, 6, 6), rotation (n_c, 6, 3, 3), gain (n_c, 6, 6) (dof, chain)."""
    for cand in range(first, stop):
        for j in range(6):
            for k in range(6):
                for col in range(6):
                    _put(out, lanes, cand - shift, j, J_COL + k, col, transform[cand, j, col, k])
                    _put(out, lanes, cand - shift, j, S_COL + k, col, shortening[cand, j, col, k])
                    _put(out, lanes, cand - shift, j, K_COL + k, col, stiffness[cand, j, col, k])
                    _put(out, lanes, cand - shift, j, T_COL + k, col,
                         0.0 if k == 0 or col == 0 else load_form[cand, j, col, k])
                    _put(out, lanes, cand - shift, j, J_ROW + k, col, transform[cand, j, k, col])
                _put(out, lanes, cand - shift, j, GAIN, k, gain[cand, k, j])
                _put(out, lanes, cand - shift, j, K_ROW0, k, stiffness[cand, j, 0, k])
            for k in range(3):
                for col in range(3):
                    _put(out, lanes, cand - shift, j, R_ROW + k, col, rotation[cand, j, k, col])
                _put(out, lanes, cand - shift, j, AXIAL_ROW, k, stiffness[cand, j, 0, k])
            for a in range(6):  # to_wrench[a, b] = sum_m sum_n<3 J[m, a] K[m, n] R[b, n]
                for b in range(3):
                    acc = 0.0
                    for m in range(6):
                        kr = 0.0
                        for n in range(3):
                            kr += stiffness[cand, j, m, n] * rotation[cand, j, b, n]
                        acc += transform[cand, j, m, a] * kr
                    _put(out, lanes, cand - shift, j, W_COL + b, a, acc)


@njit(cache=True, nogil=True)
def fill_lanes(transform, rotation, shortening, stiffness, load_form, gain, point_b, axial, compliance, wrench, defect,
               first, stop, rows4, rows, shift):
    """``consistent.lane_rows`` of candidates ``first`` to ``stop - 1`` into ``rows[cand - shift]``:
    rows (n, n_rows, 8) zeroed, then ``fill_pack``'s entries through rows4, the same memory as (n,
    n_rows / 8, WIDTH, 8), then the rows after them (``_consistent_map.c``: point_b, the axial
    stiffness, the frame's gain and compliance columns and wrench with the pose's components as
    lanes, the defect's coefficients)."""
    extra = N_PACK * WIDTH
    for cand in range(first, stop):
        for i in range(rows.shape[1]):
            for lane in range(8):
                rows[cand - shift, i, lane] = 0.0
    fill_pack(transform, rotation, shortening, stiffness, load_form, gain, first, stop, rows4, True, shift)
    for cand in range(first, stop):
        at = cand - shift
        for j in range(6):
            for k in range(3):
                rows[at, extra + k, j] = point_b[cand, j, k]
            rows[at, extra + 3, j] = axial[cand, j]
            for t in range(defect.shape[2]):
                rows[at, extra + 17 + t, j] = defect[cand, j, t]
        for k in range(6):
            for a in range(6):
                rows[at, extra + 4 + k, a] = gain[cand, a, k]
                rows[at, extra + 10 + k, a] = compliance[cand, a, k]
            rows[at, extra + 16, k] = wrench[cand, k]


@njit(inline="always", fastmath=_FAST)
def _dot3(p, row, col, a0, a1, a2):
    """sum_k a_k p[row + k, col] over three rows of a packed block."""
    return a0 * p[row, col] + a1 * p[row + 1, col] + a2 * p[row + 2, col]


@njit(inline="always", fastmath=_FAST)
def _dot5(p, row, col, a0, a1, a2, a3, a4):
    """sum_k a_k p[row + k, col] over five rows."""
    return (a0 * p[row, col] + a1 * p[row + 1, col] + a2 * p[row + 2, col] + a3 * p[row + 3, col]
            + a4 * p[row + 4, col])


@njit(inline="always", fastmath=_FAST)
def _dot6(p, row, col, a0, a1, a2, a3, a4, a5):
    """sum_k a_k p[row + k, col] over six rows: one lane of a 6x6 product (a column of the
    packed matrix times the vector a)."""
    return (a0 * p[row, col] + a1 * p[row + 1, col] + a2 * p[row + 2, col] + a3 * p[row + 3, col]
            + a4 * p[row + 4, col] + a5 * p[row + 5, col])


# inlined into ``_equilibrium`` (session 19): as a call, its 18 array arguments were passed and
# reference-counted at every evaluation, ~1/3 of the kernel's time on the random candidates
@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _terms(cand, x, c, command, x0, axial, pack, point_b, defect_index, defect, symmetric, weight, r, u, n, force, d,
           ml, grad):
    """At pose x (6,) and offsets c (3,): shortening r, axial inputs u, loads n (6,) and the
    second-order wrench ``force`` (P-delta 2 N J^T S D, the lateral defect's forces, the rigid
    term and the turning lever arms of the chain forces), all in place; force and the scratch
    vectors d, ml, grad are (WIDTH,) (entries 6, 7 unused). ``symmetric``: the defect's terms are
    ``SYMMETRIC_DEFECT``'s, written out (otherwise the loop over ``defect_index``; the same sums)."""
    t0, t1, t2 = x[3], x[4], x[5]
    xs0, xs1, xs2, xs3, xs4, xs5 = x[0], x[1], x[2], x[3], x[4], x[5]
    tt = t0 * t0 + t1 * t1 + t2 * t2
    for k in range(WIDTH):
        force[k] = 0.0
    # the weight W at the centre of gravity r turns with the frame: -d ext_r / d theta^T W
    w0, w1, w2 = weight[cand, 0], weight[cand, 1], weight[cand, 2]
    r0, r1, r2 = weight[cand, 3], weight[cand, 4], weight[cand, 5]
    tw = t0 * w0 + t1 * w1 + t2 * w2
    tr = t0 * r0 + t1 * r1 + t2 * r2
    rw = r0 * w0 + r1 * w1 + r2 * w2
    force[3] -= 0.5 * (r0 * tw + tr * w0 - 2.0 * t0 * rw)
    force[4] -= 0.5 * (r1 * tw + tr * w1 - 2.0 * t1 * rw)
    force[5] -= 0.5 * (r2 * tw + tr * w2 - 2.0 * t2 * rw)
    for j in range(6):
        p = pack[cand, j]
        pb0, pb1, pb2 = point_b[cand, j, 0], point_b[cand, j, 1], point_b[cand, j, 2]
        tp = t0 * pb0 + t1 * pb1 + t2 * pb2
        e0 = 0.5 * (t0 * tp - pb0 * tt)  # ext = 1/2 theta x (theta x p_j)
        e1 = 0.5 * (t1 * tp - pb1 * tt)
        e2 = 0.5 * (t2 * tp - pb2 * tt)
        # the 6x6 products lane by lane into locals (inlined helpers, no scratch stores between
        # them, so the compiler keeps the lanes in registers and pairs them into vector instructions)
        ec0 = _dot3(p, R_ROW, 0, e0, e1, e2)
        ec1 = _dot3(p, R_ROW, 1, e0, e1, e2)
        ec2 = _dot3(p, R_ROW, 2, e0, e1, e2)
        d0 = _dot6(p, J_COL, 0, xs0, xs1, xs2, xs3, xs4, xs5) + ec0
        d1 = _dot6(p, J_COL, 1, xs0, xs1, xs2, xs3, xs4, xs5) + ec1
        d2 = _dot6(p, J_COL, 2, xs0, xs1, xs2, xs3, xs4, xs5) + ec2
        d3 = _dot6(p, J_COL, 3, xs0, xs1, xs2, xs3, xs4, xs5)
        d4 = _dot6(p, J_COL, 4, xs0, xs1, xs2, xs3, xs4, xs5)
        d5 = _dot6(p, J_COL, 5, xs0, xs1, xs2, xs3, xs4, xs5)
        s0 = _dot6(p, S_COL, 0, d0, d1, d2, d3, d4, d5)
        s1 = _dot6(p, S_COL, 1, d0, d1, d2, d3, d4, d5)
        s2 = _dot6(p, S_COL, 2, d0, d1, d2, d3, d4, d5)
        s3 = _dot6(p, S_COL, 3, d0, d1, d2, d3, d4, d5)
        s4 = _dot6(p, S_COL, 4, d0, d1, d2, d3, d4, d5)
        s5 = _dot6(p, S_COL, 5, d0, d1, d2, d3, d4, d5)
        rr = d0 * s0 + d1 * s1 + d2 * s2 + d3 * s3 + d4 * s4 + d5 * s5
        r[j] = -rr
        u_j = r[j] + ((command[j - 3] + x0[cand, j - 3] + c[j - 3]) if j >= 3 else 0.0)
        u[j] = u_j
        # the lateral compatibility defect m_c = sum_t q_t d_a d_b (c = y..rz) and K m
        if symmetric:  # SYMMETRIC_DEFECT's terms in its order, q0..q11
            q0, q1, q2, q3 = defect[cand, j, 0], defect[cand, j, 1], defect[cand, j, 2], defect[cand, j, 3]
            q4, q5, q6, q7 = defect[cand, j, 4], defect[cand, j, 5], defect[cand, j, 6], defect[cand, j, 7]
            q8, q9, q10, q11 = defect[cand, j, 8], defect[cand, j, 9], defect[cand, j, 10], defect[cand, j, 11]
            m1 = q0 * d2 * d3 + q1 * d3 * d4
            m2 = q2 * d1 * d3 + q3 * d3 * d5
            m3 = q4 * d1 * d2 + q5 * d1 * d4 + q6 * d2 * d5 + q7 * d4 * d5
            m4 = q8 * d1 * d3 + q9 * d3 * d5
            m5 = q10 * d2 * d3 + q11 * d3 * d4
        else:
            d[0], d[1], d[2], d[3], d[4], d[5] = d0, d1, d2, d3, d4, d5
            ml[0], ml[1], ml[2], ml[3], ml[4], ml[5] = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            for t in range(defect_index.shape[0]):
                ml[defect_index[t, 0]] += defect[cand, j, t] * d[defect_index[t, 1]] * d[defect_index[t, 2]]
            m1, m2, m3, m4, m5 = ml[1], ml[2], ml[3], ml[4], ml[5]
        # K m, and the lateral chain force (K e)_c = K m - K[:, 0] u + K D (c = y..rz)
        k0 = _dot5(p, K_COL + 1, 0, m1, m2, m3, m4, m5)
        k1 = _dot5(p, K_COL + 1, 1, m1, m2, m3, m4, m5)
        k2 = _dot5(p, K_COL + 1, 2, m1, m2, m3, m4, m5)
        k3 = _dot5(p, K_COL + 1, 3, m1, m2, m3, m4, m5)
        k4 = _dot5(p, K_COL + 1, 4, m1, m2, m3, m4, m5)
        k5 = _dot5(p, K_COL + 1, 5, m1, m2, m3, m4, m5)
        f1 = (k1 - p[K_COL, 1] * u_j) + _dot6(p, K_COL, 1, d0, d1, d2, d3, d4, d5)
        f2 = (k2 - p[K_COL, 2] * u_j) + _dot6(p, K_COL, 2, d0, d1, d2, d3, d4, d5)
        f3 = (k3 - p[K_COL, 3] * u_j) + _dot6(p, K_COL, 3, d0, d1, d2, d3, d4, d5)
        f4 = (k4 - p[K_COL, 4] * u_j) + _dot6(p, K_COL, 4, d0, d1, d2, d3, d4, d5)
        f5 = (k5 - p[K_COL, 5] * u_j) + _dot6(p, K_COL, 5, d0, d1, d2, d3, d4, d5)
        load = -axial[cand, j] * u_j + k0
        load += (p[GAIN, 0] * xs0 + p[GAIN, 1] * xs1 + p[GAIN, 2] * xs2 + p[GAIN, 3] * xs3 + p[GAIN, 4] * xs4
                 + p[GAIN, 5] * xs5)
        load += p[AXIAL_ROW, 0] * ec0 + p[AXIAL_ROW, 1] * ec1 + p[AXIAL_ROW, 2] * ec2
        # the chain's own P-delta inside: energy 1/2 N^2 D^T T D with N the load above, so the
        # tension is N (1 + k q) and the shortening D^T (S + N T) D (T has no axial row)
        tq1 = _dot5(p, T_COL + 1, 1, d1, d2, d3, d4, d5)
        tq2 = _dot5(p, T_COL + 1, 2, d1, d2, d3, d4, d5)
        tq3 = _dot5(p, T_COL + 1, 3, d1, d2, d3, d4, d5)
        tq4 = _dot5(p, T_COL + 1, 4, d1, d2, d3, d4, d5)
        tq5 = _dot5(p, T_COL + 1, 5, d1, d2, d3, d4, d5)
        q = d1 * tq1 + d2 * tq2 + d3 * tq3 + d4 * tq4 + d5 * tq5
        tension = load * (1.0 + axial[cand, j] * q)
        n[j] = tension
        # the chain's energy gradient beyond the linear part and the P-delta 2 N S D: K m +
        # sum_c (K e)_c dm_c/dD, e = D - u e_x + m the chain end's strain (model/consistent.py)
        gr0 = k0 + load * (q * p[K_ROW0, 0])
        gr1 = k1 + load * (q * p[K_ROW0, 1] + load * tq1)
        gr2 = k2 + load * (q * p[K_ROW0, 2] + load * tq2)
        gr3 = k3 + load * (q * p[K_ROW0, 3] + load * tq3)
        gr4 = k4 + load * (q * p[K_ROW0, 4] + load * tq4)
        gr5 = k5 + load * (q * p[K_ROW0, 5] + load * tq5)
        if symmetric:  # sum_c f_c dm_c/dD: each term q d_a d_b gives f_c q d_b to a and f_c q d_a to b
            gr1 += f2 * q2 * d3 + f3 * q4 * d2 + f3 * q5 * d4 + f4 * q8 * d3
            gr2 += f1 * q0 * d3 + f3 * q4 * d1 + f3 * q6 * d5 + f5 * q10 * d3
            gr3 += (f1 * q0 * d2 + f1 * q1 * d4 + f2 * q2 * d1 + f2 * q3 * d5 + f4 * q8 * d1 + f4 * q9 * d5
                    + f5 * q10 * d2 + f5 * q11 * d4)
            gr4 += f1 * q1 * d3 + f3 * q5 * d1 + f3 * q7 * d5 + f5 * q11 * d3
            gr5 += f2 * q3 * d3 + f3 * q6 * d2 + f3 * q7 * d4 + f4 * q9 * d3
        else:
            grad[0], grad[1], grad[2], grad[3], grad[4], grad[5] = gr0, gr1, gr2, gr3, gr4, gr5
            ml[1], ml[2], ml[3], ml[4], ml[5] = f1, f2, f3, f4, f5
            for t in range(defect_index.shape[0]):
                ia, ib = defect_index[t, 1], defect_index[t, 2]
                w = ml[defect_index[t, 0]] * defect[cand, j, t]
                grad[ia] += w * d[ib]
                grad[ib] += w * d[ia]
            gr0, gr1, gr2, gr3, gr4, gr5 = grad[0], grad[1], grad[2], grad[3], grad[4], grad[5]
        two_t = 2.0 * tension
        v0 = two_t * s0 + gr0
        v1 = two_t * s1 + gr1
        v2 = two_t * s2 + gr2
        v3 = two_t * s3 + gr3
        v4 = two_t * s4 + gr4
        v5 = two_t * s5 + gr5
        force[0] += _dot6(p, J_ROW, 0, v0, v1, v2, v3, v4, v5) + _dot3(p, W_COL, 0, e0, e1, e2)
        force[1] += _dot6(p, J_ROW, 1, v0, v1, v2, v3, v4, v5) + _dot3(p, W_COL, 1, e0, e1, e2)
        force[2] += _dot6(p, J_ROW, 2, v0, v1, v2, v3, v4, v5) + _dot3(p, W_COL, 2, e0, e1, e2)
        force[3] += _dot6(p, J_ROW, 3, v0, v1, v2, v3, v4, v5) + _dot3(p, W_COL, 3, e0, e1, e2)
        force[4] += _dot6(p, J_ROW, 4, v0, v1, v2, v3, v4, v5) + _dot3(p, W_COL, 4, e0, e1, e2)
        force[5] += _dot6(p, J_ROW, 5, v0, v1, v2, v3, v4, v5) + _dot3(p, W_COL, 5, e0, e1, e2)
        # the chain force F (tension n_j along the axis, lateral K e) works through the second-order
        # displacement of B: d ext / d theta^T F = 1/2 (p (theta.F) + (theta.p) F - 2 theta (p.F))
        g0 = p[R_ROW, 0] * tension + p[R_ROW, 1] * f1 + p[R_ROW, 2] * f2
        g1 = p[R_ROW + 1, 0] * tension + p[R_ROW + 1, 1] * f1 + p[R_ROW + 1, 2] * f2
        g2 = p[R_ROW + 2, 0] * tension + p[R_ROW + 2, 1] * f1 + p[R_ROW + 2, 2] * f2
        tf = t0 * g0 + t1 * g1 + t2 * g2
        pf = pb0 * g0 + pb1 * g1 + pb2 * g2
        force[3] += 0.5 * (pb0 * tf + tp * g0 - 2.0 * t0 * pf)
        force[4] += 0.5 * (pb1 * tf + tp * g1 - 2.0 * t1 * pf)
        force[5] += 0.5 * (pb2 * tf + tp * g2 - 2.0 * t2 * pf)


# inlined into ``solve`` (session 38): as a call, numba linked a second copy of it into ``solve``
# and optimised that one again, whose fused multiply-adds rounded otherwise, so ``solve``
# compiled in the running process gave other last bits than loaded from numba's cache
@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _equilibrium(cand, x, c, command, compliance, wrench, x0, gain, axial, pack, point_b, defect_index, defect,
                 symmetric, weight, tol, max_iter, divergence, settle, r, u, n, force, d, ml, grad, work, secant):
    """Solve the pose x in place to ``tol`` at fixed offsets c: the fixed point ``x = Phi(x)``
    (module docstring), converged when ``|Phi(x) - x| <= tol``; x is then the last point evaluated
    (within ``tol / (1 - rho)`` of the fixed point, rho <= 0.1 the map's contraction) and r, u, n,
    force are those of it. Returns (status code, iterations = evaluations of Phi). (Before session
    15 x was moved to ``Phi(x)`` and Phi evaluated once more there: 20-23 % of all evaluations,
    for a pose change <= tol.)

    The steps are Broyden's (``x += B (Phi(x) - x)``, B ~ (I - dPhi/dx)^-1 kept in ``secant``
    (6, 6) from call to call and updated by the secant condition at each step): Phi contracts
    by only 0.04-0.09 per step here (its Jacobian's spectral radius on the standard trajectory),
    the secant steps converge superlinearly. A step that does not halve the residual resets B to
    the identity, i.e. to the plain fixed-point step. work (6, 6) scratch."""
    x_new, f_prev, s_prev, b_y, s_b, rhs = work[0], work[1], work[2], work[3], work[4], work[5]
    previous = np.inf
    for it in range(max_iter):
        _terms(cand, x, c, command, x0, axial, pack, point_b, defect_index, defect, symmetric, weight, r, u, n, force,
               d, ml, grad)
        for m in range(6):  # F_C + sum_j g_j u_j - f2(x)
            acc = wrench[cand, m] - force[m]
            for j in range(6):
                acc += gain[cand, m, j] * u[j]
            rhs[m] = acc
        change = 0.0
        for k in range(6):
            acc = 0.0
            for m in range(6):
                acc += compliance[cand, k, m] * rhs[m]
            x_new[k] = acc
            change = max(change, abs(acc - x[k]))
        r_max = 0.0
        for j in range(6):
            r_max = max(r_max, abs(r[j]))
        if not np.isfinite(change) or r_max > divergence:
            for k in range(6):
                x[k] = x_new[k]
            return DIVERGED, it + 1
        if change <= tol:
            if settle:  # x moved to Phi(x), ~rho tol from the fixed point, and its terms
                for k in range(6):
                    x[k] = x_new[k]
                _terms(cand, x, c, command, x0, axial, pack, point_b, defect_index, defect, symmetric, weight, r, u, n,
                       force, d, ml, grad)
            return OK, it + 1
        # residual f = Phi(x) - x, kept in x_new
        for k in range(6):
            x_new[k] -= x[k]
        if it > 0:
            if change > 0.5 * previous:  # the secant model did not help: plain fixed-point steps again
                for a_ in range(6):
                    for b_ in range(6):
                        secant[a_, b_] = 1.0 if a_ == b_ else 0.0
            else:  # B+ = B - (s + B y) (s^T B) / (s^T B y), y = f - f_prev: then B+ y = -s
                for a_ in range(6):
                    acc = 0.0
                    acc2 = 0.0
                    for b_ in range(6):
                        acc += secant[a_, b_] * (x_new[b_] - f_prev[b_])
                        acc2 += s_prev[b_] * secant[b_, a_]
                    b_y[a_] = acc
                    s_b[a_] = acc2
                denominator = 0.0
                scale = 0.0
                for a_ in range(6):
                    denominator += s_prev[a_] * b_y[a_]
                    scale += s_prev[a_] * s_prev[a_]
                if abs(denominator) > 1e-3 * scale:  # |B y| ~ |s|: a well-posed update
                    for a_ in range(6):
                        row = (s_prev[a_] + b_y[a_]) / denominator
                        for b_ in range(6):
                            secant[a_, b_] -= row * s_b[b_]
        for a_ in range(6):
            acc = 0.0
            for b_ in range(6):
                acc += secant[a_, b_] * x_new[b_]
            s_prev[a_] = acc
            f_prev[a_] = x_new[a_]
        for k in range(6):
            x[k] += s_prev[k]
        previous = change
    return NOT_CONVERGED, max_iter


@njit(inline="always", nogil=True)
def _status(packed):
    """(point_status code, evaluations) of ``consistent_native.equilibrium``'s packed return."""
    status = packed % 4
    return (OK if status == 0 else (NOT_CONVERGED if status == 1 else DIVERGED)), packed // 4


@njit(cache=True, nogil=True, fastmath=_FAST)
def solve(first, stop, compliance, wrench, gain, axial, pack, native, n_rows, transform, rotation, shortening,
          stiffness, load_form, point_b, defect_index, defect, symmetric, weight,
          coupling, mu, limit,
          x0, nut, band, play, inputs, revisit, clearance, tol, max_iter, divergence,
          faces, state_tol, input_gain, reuse_rates,
          pose_out, load_out, c_out, release_out, r_out, state_out, class_out, code_out, iter_out):
    """Candidates ``first`` to ``stop - 1`` (one thread each call; ``consistent`` runs a call per
    thread, and candidates share nothing) at all points (in order). Each fixed point starts from the
    previous solution moved by the response to what changed: the linear model's ``input_gain``
    (n_c, 6, 6), dX/du_j, to the command's step (plus the previous points' second-order drift),
    the last probe's measured dX/dC_k to an offset's step or a probe's. A start off by the
    change's second-order part only needs fewer fixed-point steps; where they end is unchanged.
    Inside a leg of equal steps the drift is extrapolated (linear, quadratic, then cubic in the
    step count). A point whose command an earlier point had (``revisit`` (n_p,), the latest such
    point or -1; ``consistent.revisits``: the same to 1 pm) starts from that point's equilibrium
    (moved by the linear response to the commands' difference) when the nut offsets are those it
    ended with there: the same equations, so the start is the fixed point to that difference (the
    legs' way back; session 16)."""
    n_p = inputs.shape[0]
    inner_tol = INNER_SHARE * tol
    # the C copy (``consistent_native``; where ``native``) reaches its arrays by address (an array
    # argument costs a reference count pair at each call). Every array whose address it takes is
    # used in the candidate loop's numba code too (these three at each candidate's start), which
    # keeps it allocated through that loop. Its lane rows (``consistent.lane_rows``, n_rows of them)
    # are filled per candidate into ``block`` from the pack's sources (transform, rotation,
    # shortening, stiffness, load_form, ...), where they stay in the core's cache (session 43: the
    # whole batch's rows before the solve, 6.6 MB for 300 candidates, cost ~1.5 ms on 2 threads)
    context = np.zeros(8, dtype=np.int64)  # the candidate's read-only arguments: CONTEXT's slots
    block = np.zeros((1, n_rows if native else 0, 8))
    block4 = block.reshape((1, block.shape[1] // WIDTH, WIDTH, 8))
    secant_lanes = np.zeros((6, WIDTH))  # the C copy's B as columns, padded to vector lanes
    for cand in range(first, stop):
        x = np.zeros(6)
        work = np.zeros((6, 6))
        secant = np.eye(6)
        response = np.empty((3, 6))  # dX/dC_k: the linear model's, then as the last probe measured it
        for k in range(3):
            for m in range(6):
                response[k, m] = input_gain[cand, m, 3 + k]
        drift = np.zeros(6)
        drift_prev = np.zeros(6)
        drift_prev2 = np.zeros(6)
        drift_prev3 = np.zeros(6)
        x_seen = np.empty((n_p, 6))  # every point's solution, for a later point with the same command
        c_seen = np.empty((n_p, 3))
        uniform = 0
        x_start = np.zeros(6)
        last_step = np.zeros(3)
        c_start = np.zeros(3)
        x_probe = np.zeros(6)
        u = np.zeros(6)
        r = np.zeros(6)
        n = np.zeros(6)
        n_probe = np.zeros(6)
        c = np.zeros(3)
        c_new = np.zeros(3)
        c_probe = np.zeros(3)
        c_prev = np.zeros(3)
        rate = np.zeros((3, 3))
        rate_point = np.full(3, -1, dtype=np.int64)  # the point where column k of rate was last measured tight
        reuse = np.zeros(3, dtype=np.bool_)
        stiff = np.zeros(3)
        b = np.zeros((3, 3))
        a = np.zeros(3)
        lo = np.zeros(3)
        hi = np.zeros(3)
        band_n = np.zeros(3)
        status = np.zeros(3, dtype=np.int64)
        side = np.zeros(3)
        lo2 = np.zeros(3)
        hi2 = np.zeros(3)
        a2 = np.zeros(3)
        trial = np.zeros(3)
        d = np.zeros(WIDTH)
        ml = np.zeros(WIDTH)
        grad = np.zeros(WIDTH)
        force = np.zeros(WIDTH)
        if native:
            fill_lanes(transform, rotation, shortening, stiffness, load_form, gain, point_b, axial, compliance, wrench,
                       defect, cand, cand + 1, block4, block, cand)
            context[0], context[1], context[2] = cand, 0, block.ctypes.data  # (x0, weight: row cand)
            context[3], context[4], context[5] = x0.ctypes.data, weight.ctypes.data, defect_index.shape[0]
            context[6], context[7] = defect_index.ctypes.data, 1 if symmetric else 0
        # the C copy's per-candidate arrays as addresses, taken once (each ``.ctypes`` at a call cost
        # a reference count pair too); each is used in the point loop's numba code, which keeps it
        # allocated through that loop
        context_at, x_at, c_at, n_at = context.ctypes.data, x.ctypes.data, c.ctypes.data, n.ctypes.data
        r_at, u_at, force_at = r.ctypes.data, u.ctypes.data, force.ctypes.data
        for k in range(6):
            for m in range(WIDTH):
                secant_lanes[k, m] = 1.0 if k == m else 0.0
        secant_at, inputs_at = secant_lanes.ctypes.data, inputs.ctypes.data
        x_probe_at, c_probe_at, n_probe_at = x_probe.ctypes.data, c_probe.ctypes.data, n_probe.ctypes.data
        a_at, b_at, lo_at, hi_at = a.ctypes.data, b.ctypes.data, lo.ctypes.data, hi.ctypes.data
        c_prev_at, band_n_at, side_at = c_prev.ctypes.data, band_n.ctypes.data, side.ctypes.data
        status_at, c_new_at = status.ctypes.data, c_new.ctypes.data
        use_clearance = False
        if clearance:
            for i in range(3):
                if limit[cand, i] > 0 and mu[cand, i] > 0:
                    use_clearance = True
        for i in range(3):
            lo[i] = 0.0
            hi[i] = max(limit[cand, i], 0.0)
        for p in range(n_p):
            command = inputs[p]
            along = 0.0
            size = 0.0
            length = 0.0
            for i in range(3):
                stiff[i] = nut[cand, i]
                # the start: the previous point's pose + the linear response to the command's step
                # (at the first point the linear solution from rest, X_g + H u) + the previous
                # point's second-order drift scaled by the steps' ratio (-1 at a reversal), or
                # extrapolated from the last two or three drifts inside a leg of equal steps
                step_i = command[i] - (inputs[p - 1, i] if p > 0 else -x0[cand, i] - c[i])
                along += step_i * last_step[i]
                size += last_step[i] * last_step[i]
                length += step_i * step_i
                last_step[i] = step_i
                c_start[i] = c[i]
                for k in range(6):
                    x[k] += input_gain[cand, k, 3 + i] * step_i
            if p == 0:
                for k in range(6):
                    for m in range(6):
                        x[k] += compliance[cand, k, m] * wrench[cand, m]
            for k in range(6):
                x_start[k] = x[k]
            if size > 0.0 and abs(along - size) <= 1e-9 * size and abs(length - size) <= 1e-9 * size:
                uniform += 1  # equal steps in a row
            else:
                uniform = 0
            seen = revisit[p]
            if seen >= 0:  # the same command and offsets solved before: the same equilibrium
                for i in range(3):
                    if c_seen[seen, i] != c[i]:
                        seen = -1
            if seen >= 0:  # moved by the linear response to the commands' difference (<= REVISIT_TOLERANCE)
                for k in range(6):
                    x[k] = x_seen[seen, k]
                    for i in range(3):
                        x[k] += input_gain[cand, k, 3 + i] * (command[i] - inputs[seen, i])
            elif p > 0 and size > 0.0:
                for k in range(6):
                    if uniform >= 4:  # the drift extrapolated as a cubic in the step count
                        x[k] += 4.0 * drift[k] - 6.0 * drift_prev[k] + 4.0 * drift_prev2[k] - drift_prev3[k]
                    elif uniform >= 3:  # the drift extrapolated as a quadratic in the step count
                        x[k] += 3.0 * drift[k] - 3.0 * drift_prev[k] + drift_prev2[k]
                    elif uniform == 2:
                        x[k] += 2.0 * drift[k] - drift_prev[k]
                    else:
                        x[k] += along / size * drift[k]
            code = NOT_CONVERGED
            iterations = 0
            for step in range(MAX_NEWTON if use_clearance else 1):
                # a probe follows (a nut off its flank): its rate (N_probe - N) / TANGENT_STEP needs
                # this N settled too (without, the rates' error moved C by up to 3e-12 m)
                probed = False
                if use_clearance:
                    for k in range(3):
                        if mu[cand, k] > 0 and c[k] > state_tol:
                            probed = True
                loose = probed and step == 0
                # a loose first step reuses the previous point's last tight rates of a nut that was
                # off its flank there too instead of probing it (session 19): that step only moves C
                # towards the solution, the tight steps after it measure their own. (Reusing a tight
                # step's rates at the next tight step of a point when C moved by <= 1e-12 m since
                # moved the poses by 5.6e-13 rad against a 30x tighter solve: not kept.)
                for k in range(3):
                    reuse[k] = (reuse_rates and loose and p > 0 and rate_point[k] == p - 1
                                and mu[cand, k] > 0 and c[k] > state_tol)
                # every nut on its flank: the pose to the point's own tolerance (the offsets' Newton
                # steps, which need it 1/INNER_SHARE tighter, follow only where a nut leaves its flank)
                pose_tol = LOOSE_TOL if loose else (inner_tol if probed else tol)
                if native:
                    code, its = _status(equilibrium(context_at, x_at, c_at, n_at, r_at, u_at, force_at, secant_at,
                                                    inputs_at, p, pose_tol, max_iter, divergence,
                                                    1 if probed and not loose else 0))
                else:
                    code, its = _equilibrium(cand, x, c, command, compliance, wrench, x0, gain, axial, pack, point_b,
                                             defect_index, defect, symmetric, weight, pose_tol, max_iter,
                                             divergence, probed and not loose, r, u, n, force, d, ml, grad, work,
                                             secant)
                iterations += its
                if code != OK or not use_clearance:
                    break
                # load rates dN_i / dC_k: measured on the equilibrium for the nuts off their
                # flank (in the gap or at the far wall), the linear model's (coupling, -s on the
                # diagonal) for the others (an engaged nut needs only the sign of its load; one
                # that leaves its flank is measured at the next step)
                for k in range(3):
                    if reuse[k]:
                        continue
                    if mu[cand, k] > 0 and c[k] > state_tol:
                        for m in range(6):
                            x_probe[m] = x[m] + response[k, m] * TANGENT_STEP
                        for i in range(3):
                            c_probe[i] = c[i]
                        c_probe[k] += TANGENT_STEP
                        if native:
                            code, its = _status(equilibrium(context_at, x_probe_at, c_probe_at, n_probe_at, r_at,
                                                            u_at, force_at, secant_at, inputs_at, p,
                                                            LOOSE_TOL if loose else PROBE_TOL, max_iter, divergence,
                                                            0 if loose else 1))
                        else:
                            code, its = _equilibrium(cand, x_probe, c_probe, command, compliance, wrench, x0, gain,
                                                     axial, pack, point_b, defect_index, defect, symmetric, weight,
                                                     LOOSE_TOL if loose else PROBE_TOL, max_iter, divergence,
                                                     not loose, r, u, n_probe, force, d, ml, grad, work, secant)
                        iterations += its
                        if code != OK:
                            break
                        for i in range(3):
                            rate[i, k] = (n_probe[3 + i] - n[3 + i]) / TANGENT_STEP
                        for m in range(6):
                            response[k, m] = (x_probe[m] - x[m]) / TANGENT_STEP
                        rate_point[k] = -1 if loose else p
                    else:
                        for i in range(3):
                            rate[i, k] = coupling[cand, i, k] - (axial[cand, 3 + i] if i == k else 0.0)
                        rate_point[k] = -1
                if code != OK:
                    break
                # Eq. 6-7 with the nut's own stiffness k_i = -dN_i/dC_i at this equilibrium:
                # release rho = C + N / k, linearised rho(C') = rho + (I + diag(1/k) dN/dC)(C' - C),
                # whose diagonal vanishes: C' = clip(play(C_prev, a + B C', band / k))
                for i in range(3):
                    stiff[i] = -rate[i, i] if -rate[i, i] > MIN_STIFFNESS * nut[cand, i] else nut[cand, i]
                    acc = c[i] + n[3 + i] / stiff[i]
                    for k in range(3):
                        b[i, k] = mu[cand, i] * rate[i, k] / stiff[i] if i != k else 0.0
                        if i != k:
                            acc -= rate[i, k] / stiff[i] * c[k]
                    a[i] = mu[cand, i] * acc
                    band_n[i] = band[cand, i] * nut[cand, i] / stiff[i]
                amax = 0.0
                for i in range(3):
                    amax = max(amax, abs(a[i]))
                box_tol = 1e-13 + 1e-13 * amax
                for i in range(3):
                    c_new[i] = c[i]
                if native:
                    ok = offsets(a_at, b_at, lo_at, hi_at, c_prev_at, band_n_at, side_at, status_at, box_tol,
                                 c_new_at, 1 if play and p > 0 else 0, 1 if step == 0 else 0) != 0
                elif play and p > 0:
                    ok = solve_play(a, b, lo, hi, c_prev, band_n, side, lo2, hi2, a2, status, box_tol, c_new, faces,
                                    trial, step == 0)
                else:
                    ok = solve_box(a, b, lo, hi, status, box_tol, c_new, faces, trial)
                if not ok:
                    code = CLEARANCE_FAILED
                    break
                change = 0.0
                for i in range(3):
                    change = max(change, abs(c_new[i] - c[i]))
                    for k in range(6):  # the start of the next equilibrium (see the docstring)
                        x[k] += response[i, k] * (c_new[i] - c[i])
                    c[i] = c_new[i]
                if loose:  # a first step at the loose tolerance: the next one at the tight ones
                    code = NOT_CONVERGED
                    continue
                if change == 0.0:
                    break
                if change <= tol:  # the offsets moved by <= tol: one more equilibrium settles the pose
                    if native:
                        code, its = _status(equilibrium(context_at, x_at, c_at, n_at, r_at, u_at, force_at,
                                                        secant_at, inputs_at, p, inner_tol, max_iter, divergence, 0))
                    else:
                        code, its = _equilibrium(cand, x, c, command, compliance, wrench, x0, gain, axial, pack,
                                                 point_b, defect_index, defect, symmetric, weight, inner_tol,
                                                 max_iter, divergence, False, r, u, n, force, d, ml, grad, work,
                                                 secant)
                    iterations += its
                    break
                code = NOT_CONVERGED
            for k in range(6):
                pose_out[cand, p, k] = x[k]
            for j in range(6):
                load_out[cand, p, j] = n[j]
                r_out[cand, p, j] = r[j]
            in_clearance = False
            compressed = True
            for i in range(3):
                c_out[cand, p, i] = c[i]
                release_out[cand, p, i] = c[i] + n[3 + i] / (stiff[i] if use_clearance else nut[cand, i])
                size = abs(c[i])
                if size <= state_tol:
                    state_out[cand, p, i] = 0
                elif limit[cand, i] > 0 and size >= limit[cand, i] - state_tol:
                    state_out[cand, p, i] = 2
                else:
                    state_out[cand, p, i] = 1
                if state_out[cand, p, i] > 0:
                    in_clearance = True
                if n[3 + i] >= 0:
                    compressed = False
                c_prev[i] = c[i]
            class_out[cand, p] = 2 if in_clearance else (1 if compressed else 3)
            for k in range(6):  # the second-order part of this point's change (beyond the linear start)
                drift_prev3[k] = drift_prev2[k]
                drift_prev2[k] = drift_prev[k]
                drift_prev[k] = drift[k]
                drift[k] = x[k] - x_start[k]
                for i in range(3):
                    drift[k] -= input_gain[cand, k, 3 + i] * (c[i] - c_start[i])
            code_out[cand, p] = code
            for k in range(6):
                x_seen[p, k] = x[k]
            for i in range(3):
                c_seen[p, i] = c[i]
            iter_out[cand, p] = iterations
