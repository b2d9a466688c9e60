"""numba kernel of ``consistent.py``: the per-point equilibrium with the chains' second-order
shortening, the P-delta and the rigid second-order frame kinematics solved inside the fixed
point together with the clearance (and its play state). See ``consistent.py``."""

import numpy as np
from numba import njit, prange

from ._numba_kernels import solve_box, solve_play
from .point_status import CLEARANCE_FAILED, DIVERGED, NOT_CONVERGED, OK

_FAST = {"reassoc", "contract", "arcp"}


@njit(cache=True, nogil=True, parallel=True, fastmath=_FAST)
def solve(compliance, wrench, gain, axial, transform, shortening, rotation, point_b, axial_row, to_wrench,
          load_gain_d, scale, coupling, limit, x0, nut, band, play, inputs, clearance, tol, max_iter, divergence,
          faces, state_tol, pose_out, load_out, c_out, release_out, r_out, state_out, class_out, code_out, iter_out):
    n_c = compliance.shape[0]
    n_p = inputs.shape[0]
    for cand in prange(n_c):
        x = np.zeros(6)
        x_new = np.zeros(6)
        u = np.zeros(6)
        r = np.zeros(6)
        n = np.zeros(6)
        c = np.zeros(3)
        c_prev = np.zeros(3)
        a = np.zeros(3)
        lo = np.zeros(3)
        hi = np.zeros(3)
        status = np.zeros(3, dtype=np.int64)
        side = np.zeros(3)
        lo2 = np.zeros(3)
        hi2 = np.zeros(3)
        a2 = np.zeros(3)
        trial = np.zeros(3)
        d = np.zeros(6)
        sd = np.zeros(6)
        ext = np.zeros(3)
        ext_c = np.zeros(3)
        force = np.zeros(6)
        use_clearance = False
        if clearance:
            for i in range(3):
                if limit[cand, i] > 0 and scale[cand, i] > 0:
                    use_clearance = True
        b = coupling[cand]
        for i in range(3):
            lo[i] = 0.0
            hi[i] = max(limit[cand, i], 0.0)
        for p in range(n_p):
            code = NOT_CONVERGED
            iterations = 0
            for it in range(max_iter):
                iterations = it + 1
                # chain ends: D_j = J_j X + [R_j^T ext_j; 0], ext = 1/2 theta x (theta x p_j)
                t0, t1, t2 = x[3], x[4], x[5]
                tt = t0 * t0 + t1 * t1 + t2 * t2
                for k in range(6):
                    force[k] = 0.0
                for j in range(6):
                    pb0, pb1, pb2 = point_b[cand, j, 0], point_b[cand, j, 1], point_b[cand, j, 2]
                    tp = t0 * pb0 + t1 * pb1 + t2 * pb2
                    ext[0] = 0.5 * (t0 * tp - pb0 * tt)
                    ext[1] = 0.5 * (t1 * tp - pb1 * tt)
                    ext[2] = 0.5 * (t2 * tp - pb2 * tt)
                    for a_ in range(3):
                        ext_c[a_] = (rotation[cand, j, 0, a_] * ext[0] + rotation[cand, j, 1, a_] * ext[1]
                                     + rotation[cand, j, 2, a_] * ext[2])
                    for a_ in range(6):
                        acc = 0.0
                        for k in range(6):
                            acc += transform[cand, j, a_, k] * x[k]
                        d[a_] = acc + (ext_c[a_] if a_ < 3 else 0.0)
                    rr = 0.0
                    for a_ in range(6):
                        acc = 0.0
                        for k in range(6):
                            acc += shortening[cand, j, a_, k] * d[k]
                        sd[a_] = acc
                        rr += d[a_] * acc
                    r[j] = -rr
                    u[j] = r[j] + ((inputs[p, j - 3] + x0[cand, j - 3] + c[j - 3]) if j >= 3 else 0.0)
                    load = -axial[cand, j] * u[j]
                    for k in range(6):
                        load += gain[cand, k, j] * x[k]
                    for a_ in range(3):
                        load += axial_row[cand, j, a_] * ext_c[a_]
                    n[j] = load
                    # P-delta 2 N J^T S D and the rigid term's wrench (to_wrench ext)
                    for k in range(6):
                        acc = 0.0
                        for a_ in range(6):
                            acc += transform[cand, j, a_, k] * sd[a_]
                        force[k] += 2.0 * load * acc
                        force[k] += (to_wrench[cand, j, k, 0] * ext[0] + to_wrench[cand, j, k, 1] * ext[1]
                                     + to_wrench[cand, j, k, 2] * ext[2])
                if use_clearance:
                    amax = 0.0
                    for i in range(3):  # release target mu N(C = 0) / s from the current loads
                        acc = n[3 + i]
                        for k in range(3):
                            acc -= load_gain_d[cand, i, k] * c[k]
                        a[i] = scale[cand, i] * acc
                        amax = max(amax, abs(a[i]))
                    box_tol = 1e-13 + 1e-13 * amax
                    if play and p > 0:
                        ok = solve_play(a, b, lo, hi, c_prev, band[cand], side, lo2, hi2, a2, status, box_tol, c,
                                        faces, trial, it == 0)
                    else:
                        ok = solve_box(a, b, lo, hi, status, box_tol, c, faces, trial)
                    if not ok:
                        code = CLEARANCE_FAILED
                        break
                # X = K^-1 (F_C + sum_j g_j u_j - f2), with u holding the new C
                for j in range(3, 6):
                    u[j] = r[j] + inputs[p, j - 3] + x0[cand, j - 3] + c[j - 3]
                change = 0.0
                for k in range(6):
                    acc = 0.0
                    for m in range(6):
                        rhs = wrench[cand, m] - force[m]
                        for j in range(6):
                            rhs += gain[cand, m, j] * u[j]
                        acc += compliance[cand, k, m] * rhs
                    x_new[k] = acc
                    change = max(change, abs(acc - x[k]))
                r_max = 0.0
                for j in range(6):
                    r_max = max(r_max, abs(r[j]))
                for k in range(6):
                    x[k] = x_new[k]
                if not np.isfinite(change) or r_max > divergence:
                    code = DIVERGED
                    break
                if change <= tol:
                    code = OK
                    break
            # outputs at the converged state (loads recomputed at the final X)
            for k in range(6):
                pose_out[cand, p, k] = x[k]
            t0, t1, t2 = x[3], x[4], x[5]
            tt = t0 * t0 + t1 * t1 + t2 * t2
            for j in range(6):
                pb0, pb1, pb2 = point_b[cand, j, 0], point_b[cand, j, 1], point_b[cand, j, 2]
                tp = t0 * pb0 + t1 * pb1 + t2 * pb2
                ext[0] = 0.5 * (t0 * tp - pb0 * tt)
                ext[1] = 0.5 * (t1 * tp - pb1 * tt)
                ext[2] = 0.5 * (t2 * tp - pb2 * tt)
                load = -axial[cand, j] * u[j]
                for k in range(6):
                    load += gain[cand, k, j] * x[k]
                for a_ in range(3):
                    load += axial_row[cand, j, a_] * (rotation[cand, j, 0, a_] * ext[0] + rotation[cand, j, 1, a_] * ext[1]
                                                      + rotation[cand, j, 2, a_] * ext[2])
                load_out[cand, p, j] = load
                r_out[cand, p, j] = r[j]
            in_clearance = False
            compressed = True
            for i in range(3):
                c_out[cand, p, i] = c[i]
                release_out[cand, p, i] = (load_out[cand, p, 3 + i] + nut[cand, i] * c[i]) / nut[cand, i]
                size = abs(c[i])
                if size <= state_tol:
                    state_out[cand, p, i] = 0
                elif limit[cand, i] > 0 and size >= limit[cand, i] - state_tol:
                    state_out[cand, p, i] = 2
                else:
                    state_out[cand, p, i] = 1
                if state_out[cand, p, i] > 0:
                    in_clearance = True
                if load_out[cand, p, 3 + i] >= 0:
                    compressed = False
                c_prev[i] = c[i]
            class_out[cand, p] = 2 if in_clearance else (1 if compressed else 3)
            code_out[cand, p] = code
            iter_out[cand, p] = iterations
