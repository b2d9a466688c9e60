"""numba kernels of ``kernel.py`` (module-level so that ``cache=True`` works).

Imported only by ``kernel.py`` when the compiled engine runs; see there for the algorithm.
``solve`` is compiled with ``parallel=True`` (candidates over ``prange``): besides the
threads this lets LLVM optimize the outlined loop body (measured 3x faster than the same
loop compiled serially, even on one thread). First compilation takes ~20 s, then cached.
``_segment_entries`` repeats the formulas of ``hinge.segment_entries`` (tests hold them
equal to 1e-14); ``chain_entries`` sums Eq. 1 with ``model.serial``'s own functions, compiled.
Status codes: ``point_status`` (0 converged, 1 no convergence in max_iter, 2 diverged, 3 clearance failed).
"""

import numpy as np
from numba import njit, prange

from . import serial
from .point_status import CLEARANCE_FAILED, DIVERGED, NOT_CONVERGED, OK

# the files whose code or constants these cached kernels compile in, with a digest of their text
# (numba keys its cache by this file's text only: tests/test_numba_cache_keys.py)
SOURCES_COMPILED_IN = {"serial.py": "1ff40370185d149e", "point_status.py": "9ba9d4aa3a906f93"}

# reassociation and fused multiply-add, but no "no NaN/inf" assumptions: divergence and NaN
# checks must survive optimization
_FAST = {"reassoc", "contract", "arcp"}


@njit(inline="always", cache=True, nogil=True, fastmath=_FAST)
def face_values(status, a, b, lo, hi, out):
    """C on the face ``status`` (0 lower, 1 free, 2 upper) into ``out``; False if singular.

    Free chains solve (I - B_FF) C_F = a_F + B_F,clamped C_clamped (Cramer, no allocation).
    """
    for i in range(3):
        out[i] = lo[i] if status[i] == 0 else (hi[i] if status[i] == 2 else 0.0)
    r0 = a[0] + b[0, 1] * out[1] + b[0, 2] * out[2]
    r1 = a[1] + b[1, 0] * out[0] + b[1, 2] * out[2]
    r2 = a[2] + b[2, 0] * out[0] + b[2, 1] * out[1]
    f0, f1, f2 = status[0] == 1, status[1] == 1, status[2] == 1
    n_free = int(f0) + int(f1) + int(f2)
    if n_free == 0:
        return True
    if n_free == 1:  # B_ii = 0: the free chain's equation is explicit
        if f0:
            out[0] = r0
        elif f1:
            out[1] = r1
        else:
            out[2] = r2
        return True
    # identity-padded 3x3: rows/columns of clamped chains are the unit vectors
    m01 = -b[0, 1] if (f0 and f1) else 0.0
    m02 = -b[0, 2] if (f0 and f2) else 0.0
    m10 = -b[1, 0] if (f1 and f0) else 0.0
    m12 = -b[1, 2] if (f1 and f2) else 0.0
    m20 = -b[2, 0] if (f2 and f0) else 0.0
    m21 = -b[2, 1] if (f2 and f1) else 0.0
    s0 = r0 if f0 else 0.0
    s1 = r1 if f1 else 0.0
    s2 = r2 if f2 else 0.0
    det = (1.0 - m12 * m21) - m01 * (m10 - m12 * m20) + m02 * (m10 * m21 - m20)
    if det == 0.0:
        return False
    x0 = (s0 * (1.0 - m12 * m21) - m01 * (s1 - m12 * s2) + m02 * (s1 * m21 - s2)) / det
    x1 = ((s1 - m12 * s2) - s0 * (m10 - m12 * m20) + m02 * (m10 * s2 - m20 * s1)) / det
    x2 = ((s2 - m21 * s1) - m01 * (m10 * s2 - s1 * m20) + s0 * (m10 * m21 - m20)) / det
    if f0:
        out[0] = x0
    if f1:
        out[1] = x1
    if f2:
        out[2] = x2
    return True

@njit(cache=True, nogil=True)
def face_slack(status, c, a, b, lo, hi):
    """Largest KKT violation of C on its face [m]."""
    worst = -np.inf
    for i in range(3):
        if status[i] == 1:
            v = max(lo[i] - c[i], c[i] - hi[i])
        else:
            z = a[i]
            for j in range(3):
                z += b[i, j] * c[j]
            v = z - lo[i] if status[i] == 0 else hi[i] - z
        worst = max(worst, v)
    return worst

@njit(cache=True, nogil=True)
def enumerate_box(a, b, lo, hi, status, tol, c, faces, trial):
    """Exact fallback: the face of least KKT violation among all 27; False if none fits."""
    best = np.inf
    best_face = -1
    for f in range(faces.shape[0]):
        if not face_values(faces[f], a, b, lo, hi, trial):
            continue
        slack = face_slack(faces[f], trial, a, b, lo, hi)
        if slack < best:
            best = slack
            best_face = f
            if slack <= tol:
                break
    if best_face < 0 or best > 1e-9 + tol:
        return False
    for i in range(3):
        status[i] = faces[best_face, i]
    face_values(status, a, b, lo, hi, c)
    for i in range(3):
        c[i] = min(max(c[i], lo[i]), hi[i])
    return True

@njit(inline="always", cache=True, nogil=True, fastmath=_FAST)
def solve_box(a, b, lo, hi, status, tol, c, faces, trial):
    """C = clip(a + B C, lo, hi) in place into c (status updated); False if it failed."""
    for _sweep in range(8):
        if not face_values(status, a, b, lo, hi, c):
            break
        changed = False
        for i in range(3):
            if status[i] == 1:
                if c[i] < lo[i] - tol:
                    status[i] = 0
                    changed = True
                elif c[i] > hi[i] + tol:
                    status[i] = 2
                    changed = True
            else:
                z = a[i] + b[i, 0] * c[0] + b[i, 1] * c[1] + b[i, 2] * c[2]
                if status[i] == 0 and z > lo[i] + tol:
                    status[i] = 2 if z >= hi[i] else 1
                    changed = True
                elif status[i] == 2 and z < hi[i] - tol:
                    status[i] = 0 if z <= lo[i] else 1
                    changed = True
        if not changed:
            for i in range(3):
                c[i] = min(max(c[i], lo[i]), hi[i])
            return True
    return enumerate_box(a, b, lo, hi, status, tol, c, faces, trial)

# inlined into its callers (session 39): as a call, its fifteen array arguments were reference-
# counted at every call (one per Newton step on the offsets), which doubled the second-order
# model's time with the play state; inlined, the same bits in about half the time (docs/model.md 10)
@njit(inline="always", cache=True, nogil=True, fastmath=_FAST)
def solve_play(a, b, lo, hi, c_prev, band, side, lo2, hi2, a2, status, tol, c, faces, trial, fresh):
    """C = clip(play(C_prev, a + B C, band), lo, hi) in place into c (docs/model.md 9); False if it failed.

    The play operator median(t - band, C_prev, t + band) of the target t = a + B C, clipped
    to [lo, hi], is on the rising side (t >= C_prev - band) the box problem
    ``C = clip(a - band + B C, max(lo, C_prev), hi)`` and on the falling side
    ``C = clip(a + band + B C, lo, min(hi, C_prev))``: solved exactly as a box (``solve_box``)
    for a guess of the sides, which are then checked at the solution and flipped where wrong.
    """
    if fresh:  # side guess: where the target at the previous offsets lies
        for i in range(3):
            t = a[i] + b[i, 0] * c_prev[0] + b[i, 1] * c_prev[1] + b[i, 2] * c_prev[2]
            side[i] = 1.0 if t >= c_prev[i] else -1.0
    for _attempt in range(8):
        for i in range(3):
            if side[i] > 0:
                lo2[i] = max(lo[i], c_prev[i])
                hi2[i] = hi[i]
                a2[i] = a[i] - band[i]
            else:
                lo2[i] = lo[i]
                hi2[i] = min(hi[i], c_prev[i])
                a2[i] = a[i] + band[i]
            if lo2[i] > hi2[i]:
                lo2[i] = hi2[i]
        if not solve_box(a2, b, lo2, hi2, status, tol, c, faces, trial):
            return False
        changed = False
        for i in range(3):
            t = a[i] + b[i, 0] * c[0] + b[i, 1] * c[1] + b[i, 2] * c[2]
            if side[i] > 0 and t < c_prev[i] - band[i] - tol:
                side[i] = -1.0
                changed = True
            elif side[i] < 0 and t > c_prev[i] + band[i] + tol:
                side[i] = 1.0
                changed = True
        if not changed:
            return True
    return False

@njit(cache=True, nogil=True, parallel=True, fastmath=_FAST)
def solve(q, delta_g, k_l, gain_d, n_g_d, scale, coupling, limit, x0, inputs, directions, parasitic, clearance,
          tol, max_iter, divergence, faces, input_gain, gravity_pose, load_gain, gravity_loads, nut, state_tol,
          band, play, pose_out, load_out, c_out, release_out, r_out, state_out, class_out, code_out, iter_out):
    n_c = q.shape[0]
    n_p = inputs.shape[0]
    for cand in prange(n_c):
        status = np.zeros(3, dtype=np.int64)
        lo = np.zeros(3)
        hi = np.zeros(3)
        u_in = np.zeros(6)
        delta_in = np.zeros(12)
        base0 = np.zeros(3)
        v = np.zeros(6)
        r = np.zeros(6)
        c = np.zeros(3)
        a = np.zeros(3)
        trial = np.zeros(3)
        c_prev = np.zeros(3)
        side = np.zeros(3)
        lo2 = np.zeros(3)
        hi2 = np.zeros(3)
        a2 = np.zeros(3)
        use_clearance = False
        if clearance:
            for i in range(3):
                if limit[cand, i] > 0 and scale[cand, i] > 0:
                    use_clearance = True
        b = coupling[cand]
        for p in range(n_p):
            for i in range(3):
                u_in[i] = 0.0
                u_in[3 + i] = inputs[p, i] + x0[cand, i]
                reach = directions[p, i] * limit[cand, i]
                lo[i] = min(reach, 0.0)
                hi[i] = max(reach, 0.0)
            for k in range(12):
                acc = delta_g[cand, k]
                for j in range(3, 6):
                    acc += q[cand, k, j] * u_in[j]
                delta_in[k] = acc
            for i in range(3):
                acc = n_g_d[cand, i]
                for j in range(3, 6):
                    acc += gain_d[cand, i, j] * u_in[j]
                base0[i] = acc
            if p == 0 and use_clearance:  # cold start: classify the unreleased state
                for i in range(3):
                    ai = scale[cand, i] * base0[i]
                    status[i] = 0 if ai <= lo[i] else (2 if ai >= hi[i] else 1)
            if p == 0 or not parasitic:  # later points start from the previous point's r + C
                for i in range(6):
                    v[i] = 0.0
                    r[i] = 0.0
                for i in range(3):
                    c[i] = 0.0
            code = NOT_CONVERGED
            iterations = 0
            for it in range(max_iter):
                iterations = it + 1
                if parasitic:
                    for i in range(6):
                        dy = delta_in[i]
                        dz = delta_in[6 + i]
                        for j in range(6):
                            dy += q[cand, i, j] * v[j]
                            dz += q[cand, 6 + i, j] * v[j]
                        r[i] = k_l[cand, i] * (dy * dy + dz * dz)
                if use_clearance:
                    amax = 0.0
                    for i in range(3):
                        acc = base0[i]
                        for j in range(6):
                            acc += gain_d[cand, i, j] * r[j]
                        a[i] = scale[cand, i] * acc
                        amax = max(amax, abs(a[i]))
                    box_tol = 1e-13 + 1e-13 * amax
                    if play and p > 0:
                        if not solve_play(a, b, lo, hi, c_prev, band[cand], side, lo2, hi2, a2, status, box_tol, c,
                                          faces, trial, it == 0):
                            code = CLEARANCE_FAILED
                            break
                    elif not solve_box(a, b, lo, hi, status, box_tol, c, faces, trial):
                        code = CLEARANCE_FAILED
                        break
                change = 0.0
                r_max = 0.0
                for i in range(6):
                    new = r[i] + (c[i - 3] if i >= 3 else 0.0)
                    change = max(change, abs(new - v[i]))
                    r_max = max(r_max, abs(r[i]))
                    v[i] = new
                if not parasitic:
                    code = OK
                    break
                if not np.isfinite(change) or r_max > divergence:
                    code = DIVERGED
                    break
                if change <= tol:
                    code = OK
                    break
            for i in range(6):
                u_in[i] += v[i]  # now the full axial displacement u
                r_out[cand, p, i] = r[i]
            for k in range(6):
                pose = gravity_pose[cand, k]
                load = gravity_loads[cand, k]
                for j in range(6):
                    pose += input_gain[cand, k, j] * u_in[j]
                    load += load_gain[cand, k, j] * u_in[j]
                pose_out[cand, p, k] = pose
                load_out[cand, p, k] = load
            in_clearance = False
            compressed = True
            for i in range(3):
                c_out[cand, p, i] = c[i]
                d_i = directions[p, i]
                release_out[cand, p, i] = d_i * (load_out[cand, p, 3 + i] + nut[cand, i] * c[i]) / nut[cand, i]
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
            class_out[cand, p] = 2 if in_clearance else (1 if compressed else 3)
            for i in range(3):
                c_prev[i] = c[i]
            code_out[cand, p] = code
            iter_out[cand, p] = iterations

@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def torsion(thick, width):
    short, long = min(thick, width), max(thick, width)
    ratio = short / long
    ratio2 = ratio * ratio
    return long * short * short * short * (1.0 / 3.0 - 0.21 * ratio * (1.0 - ratio2 * ratio2 / 12.0))


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _arc_sums(r, t, w, nodes, weights):
    """(int u^2/t, int u^2/t^3, int 1/J) over one circular arc of radius r from thickness t,
    Gauss-Legendre in sigma = asinh(v) (split where the torsion formula switches sides)."""
    s0 = s1 = s2 = 0.0
    tau = np.sqrt(t / (t + 4.0 * r))
    v_end = 1.0 / tau
    split = v_end
    if w > t and w < t + 2.0 * r:
        split = np.sqrt((w - t) / (t - w * tau * tau))
    n_panels = 2 if split < v_end else 1
    two_r_tau = 2.0 * r * tau
    for panel in range(n_panels):
        lo = 0.0 if panel == 0 else np.arcsinh(split)
        hi = np.arcsinh(split) if panel == 0 else np.arcsinh(v_end)
        half = 0.5 * (hi - lo)
        for n in range(nodes.shape[0]):
            e = np.exp(lo + half * (nodes[n] + 1.0))
            inv_e = 1.0 / e
            v = 0.5 * (e - inv_e)  # sinh(sigma)
            cosh = 0.5 * (e + inv_e)  # dv/dsigma
            tv2p1 = 1.0 + (tau * v) ** 2
            inv = 1.0 / tv2p1
            u = two_r_tau * v * inv
            du = half * weights[n] * cosh * two_r_tau * (2.0 - tv2p1) * inv * inv
            thick = t * cosh * cosh * inv  # 1 + v^2 = cosh^2
            inv_thick = 1.0 / thick
            u2_t = u * u * du * inv_thick
            s0 += u2_t
            s1 += u2_t * inv_thick * inv_thick
            s2 += du / torsion(thick, w)
    return s0, s1, s2


@njit(cache=True, nogil=True, fastmath=_FAST)
def arc_quadrature(radius, thickness, width, nodes, weights, out):
    """hinge._arc_quadrature for flat arrays (n,): out (n, 3) = int u^2/t, int u^2/t^3, int 1/J."""
    for k in range(radius.shape[0]):
        out[k, 0] = out[k, 1] = out[k, 2] = 0.0
        if radius[k] > 0.0:
            out[k, 0], out[k, 1], out[k, 2] = _arc_sums(radius[k], thickness[k], width[k], nodes, weights)


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _segment_entries(c, rho, t, w, e, g, kappa, nodes, weights, out):
    """hinge.segment_entries for one segment into out (8,) (same formulas, one at a time)."""
    inv_t = 1.0 / t
    flat_t1, flat_t3, flat_j = inv_t, inv_t * inv_t * inv_t, 1.0 / torsion(t, w)
    a0t1 = a0t3 = a0j = a1t1 = a1t3 = a2t1 = a2t3 = 0.0
    if rho > 0.0:
        s = rho / t  # Paros-Weisbord / Lobontiu closed forms over the arc pair, halved
        root = np.sqrt(4.0 * s + 1.0)
        arctan = np.arctan(root)
        a0t1 = 0.5 * (2.0 * (2.0 * s + 1.0) / root * arctan - 0.5 * np.pi)
        a0t3 = 0.5 * (2.0 * s * (6.0 * s * s + 4.0 * s + 1.0) / ((2.0 * s + 1.0) * (4.0 * s + 1.0) ** 2)
                      + 12.0 * s * s * (2.0 * s + 1.0) / root**5 * arctan) / (t * t)
        big_t = t + 2.0 * rho  # first moments: elementary antiderivatives
        a1t1 = 0.25 * (big_t * np.log1p(2.0 * rho / t) - 2.0 * rho)
        a1t3 = 0.25 * (0.5 * big_t * (inv_t * inv_t - 1.0 / (big_t * big_t)) - (inv_t - 1.0 / big_t))
        a2t1, a2t3, a0j = _arc_sums(rho, t, w, nodes, weights)
    m0t1 = 2.0 * c * flat_t1 + 2.0 * a0t1
    m0t3 = 2.0 * c * flat_t3 + 2.0 * a0t3
    m0j = 2.0 * c * flat_j + 2.0 * a0j
    c3 = 2.0 * c * c * c / 3.0
    m2t1 = c3 * flat_t1 + 2.0 * (c * c * a0t1 + 2.0 * c * a1t1 + a2t1)
    m2t3 = c3 * flat_t3 + 2.0 * (c * c * a0t3 + 2.0 * c * a1t3 + a2t3)
    half_len = c + rho
    shear = m0t1 / (kappa * g * w)
    bend_z0 = 12.0 * m0t3 / (e * w)
    bend_y0 = 12.0 * m0t1 / (e * w * w * w)
    out[0] = m0t1 / (e * w)
    out[1] = 12.0 * (half_len * half_len * m0t3 + m2t3) / (e * w) + shear
    out[2] = half_len * bend_z0
    out[3] = bend_z0
    out[4] = 12.0 * (half_len * half_len * m0t1 + m2t1) / (e * w * w * w) + shear
    out[5] = -half_len * bend_y0
    out[6] = bend_y0
    out[7] = m0j / g


# Eq. 1 on the eight entries: model.serial's own functions, compiled (one implementation)
_moved_along_axis = njit(inline="always", cache=True, nogil=True, fastmath=_FAST)(serial.moved_along_axis)
_quarter_turn = njit(inline="always", cache=True, nogil=True, fastmath=_FAST)(serial.quarter_turn)


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _chain_parts(length, hinge, width, fillet, thick1, thick2, section, connector, end_block, e, g, kappa, nodes,
                 weights, parts):
    """A chain's five kinds of element into parts (5, 8) (block, leaf 1, connector, leaf 2
    turned, strut: each at its loaded end, chain axes) and their lengths [m]."""
    strut = length - 2.0 * end_block - 4.0 * hinge - 2.0 * connector
    flat_leaf = max(0.5 * hinge - fillet, 0.0)
    _segment_entries(0.5 * end_block, 0.0, section, section, e, g, kappa, nodes, weights, parts[0])
    _segment_entries(flat_leaf, fillet, thick1, width, e, g, kappa, nodes, weights, parts[1])
    _segment_entries(0.5 * connector, 0.0, section, section, e, g, kappa, nodes, weights, parts[2])
    _segment_entries(flat_leaf, fillet, thick2, width, e, g, kappa, nodes, weights, parts[3])
    _segment_entries(0.5 * strut, 0.0, section, section, e, g, kappa, nodes, weights, parts[4])
    turned = _quarter_turn(parts[3])  # leaf 2 is leaf 1 turned +90 deg about x
    for i in range(8):
        parts[3, i] = turned[i]
    return end_block, hinge, connector, hinge, strut


@njit(cache=True, nogil=True, fastmath=_FAST)
def chain_entries_elements(length, hinge, width, fillet, thick1, thick2, section, connector, end_block, e, g, kappa,
                           nodes, weights, out, elements, offsets):
    """chain.chain_entries_and_elements for flat arrays (n,): out (n, 8) the chain's entries at B
    (Eq. 1 along the axis, no actuator), elements (n, 9, 8) each element's entries at its loaded
    end in the chain's axes (A -> B: block, leaf 1, connector, leaf 2 turned, strut, ...), offsets
    (n, 9) [m] that end's x minus B's. The parts as ``chain_entries`` computes them, once for
    both. One thread: a few hundred ns a chain, less than starting numba's threads."""
    kinds = (0, 1, 2, 3, 4, 3, 2, 1, 0)  # A -> B
    parts = np.zeros((5, 8))  # block, leaf1, connector, leaf2 (turned), strut
    for k in range(length.shape[0]):
        sizes = _chain_parts(length[k], hinge[k], width[k], fillet[k], thick1[k], thick2[k], section[k], connector[k],
                             end_block[k], e, g, kappa, nodes, weights, parts)
        for i in range(8):
            out[k, i] = 0.0
        end = 0.0
        for position in range(9):
            kind = kinds[position]
            end += sizes[kind]
            offsets[k, position] = end - length[k]
            for i in range(8):
                elements[k, position, i] = parts[kind, i]
            moved = _moved_along_axis(parts[kind], end - length[k])  # r_i = p_i - p_B
            for i in range(8):
                out[k, i] += moved[i]


@njit(cache=True, nogil=True, parallel=True, fastmath=_FAST)
def chain_entries(length, hinge, width, fillet, thick1, thick2, section, connector, end_block, actuator_compliance,
                  e, g, kappa, nodes, weights, out):
    """chain.chain_compliance_entries for flat arrays (n,): out (n, 8), Eq. 1 along the axis.
    Chains in parallel (numba threads; each iteration has its own scratch)."""
    kinds = (0, 1, 2, 3, 4, 3, 2, 1, 0)  # A -> B
    for k in prange(length.shape[0]):
        parts = np.zeros((5, 8))  # block, leaf1, connector, leaf2 (turned), strut
        sizes = _chain_parts(length[k], hinge[k], width[k], fillet[k], thick1[k], thick2[k], section[k], connector[k],
                             end_block[k], e, g, kappa, nodes, weights, parts)
        for i in range(8):
            out[k, i] = 0.0
        end = 0.0
        for kind in kinds:
            end += sizes[kind]
            moved = _moved_along_axis(parts[kind], end - length[k])  # r_i = p_i - p_B
            for i in range(8):
                out[k, i] += moved[i]
        out[k, 0] += actuator_compliance[k]


@njit(cache=True, nogil=True, parallel=True, fastmath=_FAST)
def assemble(stiffness, rotation, point_b, centre, wrench, transform, frame_stiffness, axial_gain, input_gain,
             gravity_pose, parasitic_rows, parasitic_gain, parasitic_gravity):
    """assembly.mechanism_matrices' linear algebra per candidate (same formulas, in place).

    stiffness (n_c, 6, 6, 6), rotation (n_c, 6, 3, 3), point_b (6, 3), centre (n_c, 6, 3),
    wrench (6,); outputs J_i, K_CC, G, H = K_CC^-1 G, X_g = K_CC^-1 F_C, P, Q = P H, P X_g.
    """
    n_c = stiffness.shape[0]
    for cand in prange(n_c):  # candidates in parallel, each with its own scratch
        kj = np.zeros((6, 6))
        rhs = np.zeros((6, 7))
        low = np.zeros((6, 6))
        kcc = frame_stiffness[cand]
        kcc[:, :] = 0.0
        for i in range(6):
            j = transform[cand, i]
            j[:, :] = 0.0
            for r in range(3):
                for col in range(3):
                    j[r, col] = rotation[cand, i, col, r]  # R^T
                    j[3 + r, 3 + col] = rotation[cand, i, col, r]
                ax, ay, az = rotation[cand, i, 0, r], rotation[cand, i, 1, r], rotation[cand, i, 2, r]
                px, py, pz = point_b[i, 0], point_b[i, 1], point_b[i, 2]
                j[r, 3] = py * az - pz * ay  # row r of -R^T [p]x = (p x r_r)^T
                j[r, 4] = pz * ax - px * az
                j[r, 5] = px * ay - py * ax
            k = stiffness[cand, i]
            for a in range(6):
                for b in range(6):
                    acc = 0.0
                    for m in range(6):
                        acc += k[a, m] * j[m, b]
                    kj[a, b] = acc
            for a in range(6):
                g = 0.0
                for m in range(6):
                    g += j[m, a] * k[m, 0]
                axial_gain[cand, a, i] = g
                for b in range(6):
                    acc = 0.0
                    for m in range(6):
                        acc += j[m, a] * kj[m, b]
                    kcc[a, b] += acc
            # parasitic rows: lateral (local y, z) displacement of the B-side flexure centre
            for row in range(2):
                r = row + 1
                ax, ay, az = rotation[cand, i, 0, r], rotation[cand, i, 1, r], rotation[cand, i, 2, r]
                px, py, pz = centre[cand, i, 0], centre[cand, i, 1], centre[cand, i, 2]
                prow = parasitic_rows[cand, 6 * row + i]
                prow[0], prow[1], prow[2] = ax, ay, az
                prow[3], prow[4], prow[5] = py * az - pz * ay, pz * ax - px * az, px * ay - py * ax
        # Cholesky of K_CC (symmetric positive definite) and solve for [G | F_C]
        for a in range(6):
            for b in range(6):
                rhs[a, b] = axial_gain[cand, a, b]
            rhs[a, 6] = wrench[a]
        for a in range(6):
            for b in range(a + 1):
                acc = kcc[a, b]
                for m in range(b):
                    acc -= low[a, m] * low[b, m]
                if a == b:
                    low[a, a] = np.sqrt(acc) if acc > 0.0 else np.nan
                else:
                    low[a, b] = acc / low[b, b]
        for col in range(7):
            for a in range(6):  # forward substitution
                acc = rhs[a, col]
                for m in range(a):
                    acc -= low[a, m] * rhs[m, col]
                rhs[a, col] = acc / low[a, a]
            for a in range(5, -1, -1):  # back substitution
                acc = rhs[a, col]
                for m in range(a + 1, 6):
                    acc -= low[m, a] * rhs[m, col]
                rhs[a, col] = acc / low[a, a]
        for a in range(6):
            for b in range(6):
                input_gain[cand, a, b] = rhs[a, b]
            gravity_pose[cand, a] = rhs[a, 6]
        for row in range(12):
            acc_g = 0.0
            for m in range(6):
                acc_g += parasitic_rows[cand, row, m] * rhs[m, 6]
            parasitic_gravity[cand, row] = acc_g
            for b in range(6):
                acc = 0.0
                for m in range(6):
                    acc += parasitic_rows[cand, row, m] * rhs[m, b]
                parasitic_gain[cand, row, b] = acc
