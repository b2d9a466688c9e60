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
plain fixed point of before) the iteration locked into 2-cycles on random candidates.
"""

import numpy as np
from numba import njit, prange

from ._numba_kernels import solve_box, solve_play
from .point_status import CLEARANCE_FAILED, DIVERGED, NOT_CONVERGED, OK

_FAST = {"reassoc", "contract", "arcp"}
TANGENT_STEP = 1e-6  # [m] offset step of the measured tangent: its second-order error ~1e-6 relative
MAX_NEWTON = 40  # Newton steps on the offsets per point (2-4 where a nut leaves its flank)
# the pose is iterated 100x tighter than the offsets' tolerance: near two free nuts with
# coupling ~0.9, (I - B)^-1 amplifies the pose's rounding by up to ~100 in the offsets
INNER_SHARE = 1e-2
PROBE_TOL = 1e-14  # [m, rad] a probe's pose: its rate error ~ 1e-12 / TANGENT_STEP x 1e8 N/m, 5e-5 relative
MIN_STIFFNESS = 0.2  # a measured nut stiffness below this share of the linear one is not trusted (linear used)


@njit(cache=True, nogil=True, fastmath=_FAST)
def _terms(cand, x, c, command, x0, gain, axial, transform, shortening, rotation, point_b, axial_row, to_wrench,
           stiffness, defect_index, defect, load_form, weight, r, u, n, force, d, sd, ext, ext_c, ml, kml, grad,
           td):
    """At pose x (6,) and offsets c (3,): shortening r, axial inputs u, loads n (6,) and the
    second-order wrench ``force`` (P-delta 2 N J^T S D, the lateral defect's forces, the rigid
    term and the turning lever arms of the chain forces), all in place."""
    t0, t1, t2 = x[3], x[4], x[5]
    tt = t0 * t0 + t1 * t1 + t2 * t2
    for k in range(6):
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
        pb0, pb1, pb2 = point_b[cand, j, 0], point_b[cand, j, 1], point_b[cand, j, 2]
        tp = t0 * pb0 + t1 * pb1 + t2 * pb2
        ext[0] = 0.5 * (t0 * tp - pb0 * tt)  # 1/2 theta x (theta x p_j)
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
        u[j] = r[j] + ((command[j - 3] + x0[cand, j - 3] + c[j - 3]) if j >= 3 else 0.0)
        # the lateral compatibility defect m_c = sum_t q_t d_a d_b (c = y..rz) and K m (6,)
        for a_ in range(6):
            ml[a_] = 0.0
        for t in range(defect_index.shape[0]):
            ml[defect_index[t, 0]] += defect[cand, j, t] * d[defect_index[t, 1]] * d[defect_index[t, 2]]
        for a_ in range(6):
            acc = 0.0
            for k in range(1, 6):
                acc += stiffness[cand, j, a_, k] * ml[k]
            kml[a_] = acc
        # the lateral chain force (K e)_c, c = y..rz, into ml (m itself is done with)
        for a_ in range(1, 6):
            acc = kml[a_] - stiffness[cand, j, a_, 0] * u[j]
            for k in range(6):
                acc += stiffness[cand, j, a_, k] * d[k]
            ml[a_] = acc
        load = -axial[cand, j] * u[j] + kml[0]
        for k in range(6):
            load += gain[cand, k, j] * x[k]
        for a_ in range(3):
            load += axial_row[cand, j, a_] * ext_c[a_]
        # the chain's own P-delta inside: energy 1/2 N^2 D^T T D with N the load above, so the
        # tension is N (1 + k q) and the shortening D^T (S + N T) D (T has no axial row)
        q = 0.0
        td[0] = 0.0
        for a_ in range(1, 6):
            acc = 0.0
            for k in range(1, 6):
                acc += load_form[cand, j, a_, k] * d[k]
            td[a_] = acc
            q += d[a_] * acc
        tension = load * (1.0 + axial[cand, j] * q)
        n[j] = tension
        # the chain's energy gradient beyond the linear part and the P-delta 2 N S D: K m +
        # sum_c (K e)_c dm_c/dD, e = D - u e_x + m the chain end's strain (model/consistent.py)
        for a_ in range(6):
            grad[a_] = kml[a_] + load * (q * stiffness[cand, j, 0, a_] + load * td[a_])
        for t in range(defect_index.shape[0]):
            ia, ib = defect_index[t, 1], defect_index[t, 2]
            w = ml[defect_index[t, 0]] * defect[cand, j, t]
            grad[ia] += w * d[ib]
            grad[ib] += w * d[ia]
        for k in range(6):
            acc = 0.0
            for a_ in range(6):
                acc += transform[cand, j, a_, k] * (2.0 * tension * sd[a_] + grad[a_])
            force[k] += acc
            force[k] += (to_wrench[cand, j, k, 0] * ext[0] + to_wrench[cand, j, k, 1] * ext[1]
                         + to_wrench[cand, j, k, 2] * ext[2])
        # the chain force F (tension n_j along the axis, lateral K e) works through the second-order
        # displacement of B: d ext / d theta^T F = 1/2 (p (theta.F) + (theta.p) F - 2 theta (p.F))
        f1 = ml[1]
        f2 = ml[2]
        g0 = rotation[cand, j, 0, 0] * tension + rotation[cand, j, 0, 1] * f1 + rotation[cand, j, 0, 2] * f2
        g1 = rotation[cand, j, 1, 0] * tension + rotation[cand, j, 1, 1] * f1 + rotation[cand, j, 1, 2] * f2
        g2 = rotation[cand, j, 2, 0] * tension + rotation[cand, j, 2, 1] * f1 + rotation[cand, j, 2, 2] * f2
        tf = t0 * g0 + t1 * g1 + t2 * g2
        pf = pb0 * g0 + pb1 * g1 + pb2 * g2
        force[3] += 0.5 * (pb0 * tf + tp * g0 - 2.0 * t0 * pf)
        force[4] += 0.5 * (pb1 * tf + tp * g1 - 2.0 * t1 * pf)
        force[5] += 0.5 * (pb2 * tf + tp * g2 - 2.0 * t2 * pf)


@njit(cache=True, nogil=True, fastmath=_FAST)
def _equilibrium(cand, x, c, command, compliance, wrench, x0, gain, axial, transform, shortening, rotation, point_b,
                 axial_row, to_wrench, stiffness, defect_index, defect, load_form, weight, tol, max_iter, divergence,
                 r, u, n, force, d, sd, ext, ext_c, ml, kml, grad, td, work, secant):
    """Solve the pose x in place to ``tol`` at fixed offsets c: the fixed point ``x = Phi(x)``
    (module docstring), converged when ``|Phi(x) - x| <= tol``; x is then ``Phi(x)`` and r, u, n,
    force are those of it. Returns (status code, iterations = evaluations of Phi).

    The steps are Broyden's (``x += B (Phi(x) - x)``, B ~ (I - dPhi/dx)^-1 kept in ``secant``
    (6, 6) from call to call and updated by the secant condition at each step): Phi contracts
    by only 0.04-0.09 per step here (its Jacobian's spectral radius on the standard trajectory),
    the secant steps converge superlinearly. A step that does not halve the residual resets B to
    the identity, i.e. to the plain fixed-point step. work (6, 6) scratch."""
    x_new, f_prev, s_prev, b_y, s_b, rhs = work[0], work[1], work[2], work[3], work[4], work[5]
    previous = np.inf
    for it in range(max_iter):
        _terms(cand, x, c, command, x0, gain, axial, transform, shortening, rotation, point_b, axial_row, to_wrench,
               stiffness, defect_index, defect, load_form, weight, r, u, n, force, d, sd, ext, ext_c, ml, kml, grad,
               td)
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
            for k in range(6):
                x[k] = x_new[k]
            _terms(cand, x, c, command, x0, gain, axial, transform, shortening, rotation, point_b, axial_row,
                   to_wrench, stiffness, defect_index, defect, load_form, weight, r, u, n, force, d, sd, ext, ext_c,
                   ml, kml, grad, td)
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


@njit(cache=True, nogil=True, parallel=True, fastmath=_FAST)
def solve(compliance, wrench, gain, axial, transform, shortening, rotation, point_b, axial_row, to_wrench,
          stiffness, defect_index, defect, load_form, weight, coupling, mu, limit, x0, nut, band, play, inputs,
          clearance, tol, max_iter, divergence,
          faces, state_tol, input_gain,
          pose_out, load_out, c_out, release_out, r_out, state_out, class_out, code_out, iter_out):
    """All candidates (in parallel) at all points (in order). Each fixed point starts from the
    previous solution moved by the response to what changed: the linear model's ``input_gain``
    (n_c, 6, 6), dX/du_j, to the command's step (plus the previous points' second-order drift),
    the last probe's measured dX/dC_k to an offset's step or a probe's. A start off by the
    change's second-order part only needs fewer fixed-point steps; where they end is unchanged."""
    n_c = compliance.shape[0]
    n_p = inputs.shape[0]
    inner_tol = INNER_SHARE * tol
    for cand in prange(n_c):
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
        d = np.zeros(6)
        sd = np.zeros(6)
        ext = np.zeros(3)
        ext_c = np.zeros(3)
        ml = np.zeros(6)
        kml = np.zeros(6)
        grad = np.zeros(6)
        td = np.zeros(6)
        force = np.zeros(6)
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
            if p > 0 and size > 0.0:
                for k in range(6):
                    if uniform >= 3:  # the drift extrapolated as a quadratic in the step count
                        x[k] += 3.0 * drift[k] - 3.0 * drift_prev[k] + drift_prev2[k]
                    elif uniform == 2:
                        x[k] += 2.0 * drift[k] - drift_prev[k]
                    else:
                        x[k] += along / size * drift[k]
            code = NOT_CONVERGED
            iterations = 0
            for step in range(MAX_NEWTON if use_clearance else 1):
                code, its = _equilibrium(cand, x, c, command, compliance, wrench, x0, gain, axial, transform,
                                         shortening, rotation, point_b, axial_row, to_wrench, stiffness, defect_index,
                                         defect, load_form, weight, inner_tol, max_iter,
                                         divergence, r, u, n, force, d, sd, ext, ext_c, ml, kml, grad, td, work, secant)
                iterations += its
                if code != OK or not use_clearance:
                    break
                # load rates dN_i / dC_k: measured on the equilibrium for the nuts off their
                # flank (in the gap or at the far wall), the linear model's (coupling, -s on the
                # diagonal) for the others (an engaged nut needs only the sign of its load; one
                # that leaves its flank is measured at the next step)
                for k in range(3):
                    if mu[cand, k] > 0 and c[k] > state_tol:
                        for m in range(6):
                            x_probe[m] = x[m] + response[k, m] * TANGENT_STEP
                        for i in range(3):
                            c_probe[i] = c[i]
                        c_probe[k] += TANGENT_STEP
                        code, its = _equilibrium(cand, x_probe, c_probe, command, compliance, wrench, x0, gain,
                                                 axial, transform, shortening, rotation, point_b, axial_row,
                                                 to_wrench, stiffness, defect_index, defect, load_form, weight,
                                                 PROBE_TOL, max_iter, divergence, r, u, n_probe, force, d, sd, ext,
                                                 ext_c, ml, kml, grad, td, work, secant)
                        iterations += its
                        if code != OK:
                            break
                        for i in range(3):
                            rate[i, k] = (n_probe[3 + i] - n[3 + i]) / TANGENT_STEP
                        for m in range(6):
                            response[k, m] = (x_probe[m] - x[m]) / TANGENT_STEP
                    else:
                        for i in range(3):
                            rate[i, k] = coupling[cand, i, k] - (axial[cand, 3 + i] if i == k else 0.0)
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
                if play and p > 0:
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
                if change == 0.0:
                    break
                if change <= tol:  # the offsets moved by <= tol: one more equilibrium settles the pose
                    code, its = _equilibrium(cand, x, c, command, compliance, wrench, x0, gain, axial, transform,
                                             shortening, rotation, point_b, axial_row, to_wrench, stiffness,
                                             defect_index, defect, load_form, weight, inner_tol, max_iter,
                                             divergence, r, u, n, force, d, sd, ext, ext_c, ml, kml, grad, td, work, secant)
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
                drift_prev2[k] = drift_prev[k]
                drift_prev[k] = drift[k]
                drift[k] = x[k] - x_start[k]
                for i in range(3):
                    drift[k] -= input_gain[cand, k, 3 + i] * (c[i] - c_start[i])
            code_out[cand, p] = code
            iter_out[cand, p] = iterations
