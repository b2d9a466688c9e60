"""The numpy engine of the per-point solve of Eq. 8 (reference implementation).

Readable and allocation-heavy; ``kernel.py`` runs the same fixed point compiled. Both are
called through ``forward``; tests hold them equal.

Fixed point on the correction ``v = r + C`` of the axial A-end displacements ``u``:
``Delta = Q v + Delta_in`` (lateral displacements of the B-side flexure centres, rows y
then z), ``r_i = -K_Li (Delta_y,i^2 + Delta_z,i^2)`` (Eq. 4-5), then the clearance
``C = clip(a + B C, lo, hi)`` with ``a = mu/s N_D(C = 0)`` (Eq. 6-7, ``clearance``). The
first ``FULL_CLEARANCE_SOLVES`` steps solve the clearance fully, later steps hold the chain
statuses (C is then affine in ``a``) and re-check them at convergence.
"""

from __future__ import annotations

import numpy as np

from .assembly import MechanismMatrices
from .clearance import ConvergenceError, FixedFaces, clearance_coupling, solve_clearance
from .parameters import DRIVING

__all__ = ["solve_points", "FULL_CLEARANCE_SOLVES"]

FULL_CLEARANCE_SOLVES = 2  # iterations with a full clearance solve before the statuses are held


def solve_points(matrices: MechanismMatrices, inputs: np.ndarray, directions: np.ndarray, *, parasitic: bool = True,
                 clearance: bool = True, tol: float = 1e-13, max_iter: int = 60, divergence: float = 1e-2,
                 candidate_offset: int = 0):
    """Solve Eq. 8 at every point for precomputed matrices (numpy reference engine).

    inputs (n_p, 3) [m]; directions (n_p, 3) [+-1] as used by the clearance. Returns
    (u (n_c, n_p, 6) [m] axial A-end displacements, C (n_c, n_p, 3) [m], r (n_c, n_p, 6) [m],
    n_iterations). ``candidate_offset`` is added to candidate indices in error messages.

    Iteration on the correction ``v = r + C`` (C in the driving rows): lateral displacements
    ``Delta = Q v + Delta_in`` -> ``r``; the clearance is then solved exactly for the new
    loads (``solve_clearance``, warm-started from the previous chain statuses). Without the
    parasitic term one pass is exact.
    """
    m = matrices
    n_c, n_p = m.n_candidates, inputs.shape[0]
    d = np.ascontiguousarray(np.asarray(directions, dtype=float).T)
    u_in = np.zeros((n_c, 6, n_p))
    u_in[:, DRIVING] = inputs.T[None] + m.initial_position[:, :, None]
    gain_d = np.ascontiguousarray(m.load_gain[:, DRIVING])  # dN_D/du (n_c, 3, 6)
    use_clearance = bool(clearance and np.any((m.clearance > 0) & (m.mu > 0)))
    r = np.zeros((n_c, 6, n_p))
    c = np.zeros((n_c, 3, n_p))
    if use_clearance:
        base0 = m.gravity_loads[:, DRIVING, None] + gain_d @ u_in  # N_D with r = 0, C = 0
        a_scale = (m.mu / m.nut_stiffness)[:, :, None]
        coupling = clearance_coupling(m.coupling[:, DRIVING, DRIVING], m.nut_stiffness, m.mu)
        reach = d[None] * m.clearance[:, :, None]
        lo, hi = np.minimum(reach, 0.0), np.maximum(reach, 0.0)
        status, faces = None, None
    if parasitic:
        u_aug = np.empty((n_c, 7, n_p))
        u_aug[:, :6] = u_in
        u_aug[:, 6] = 1.0
        delta_in = np.concatenate([m.parasitic_gain, m.parasitic_gravity[:, :, None]], axis=-1) @ u_aug
        k_l = -m.parasitic_coefficient[:, :, None]
    v = np.zeros((n_c, 6, n_p))
    iterations, change = 0, np.zeros_like(v)
    for iterations in range(1, max_iter + 1):
        if parasitic:
            delta = m.parasitic_gain @ v
            delta += delta_in
            delta *= delta
            r = k_l * (delta[:, :6] + delta[:, 6:])
        if use_clearance:
            a = a_scale * ((base0 + gain_d @ r) if parasitic else base0)
            if faces is None:  # full solves while r still moves by > ~1e-8 m, then hold the statuses
                c, status = solve_clearance(a, coupling, lo, hi, status, candidate_offset)
                if iterations >= FULL_CLEARANCE_SOLVES:
                    faces = FixedFaces(status, coupling, lo, hi)
            else:
                c = faces(a)
        if not parasitic:
            break
        v_new = r.copy()
        v_new[:, DRIVING] += c
        change = np.abs(v_new - v)
        v = v_new
        worst = float(np.max(change))
        size = np.abs(r)
        if not np.isfinite(worst) or np.max(size) > divergence:
            size = np.where(np.isfinite(size) & np.isfinite(change), size, np.inf)
            cand, _, point = np.unravel_index(np.argmax(size), size.shape)
            raise ConvergenceError(f"the parasitic iteration diverges (|r| = {float(size[cand, _, point]):.3g} m); the "
                                   f"inputs are too large for the small-deflection model",
                                   candidate=int(cand) + candidate_offset, point=int(point))
        if worst <= tol:
            if use_clearance:  # re-check the held statuses at the converged loads
                c_checked, status = solve_clearance(a, coupling, lo, hi, status, candidate_offset)
                if faces is None or np.any(status != faces.status):
                    faces = FixedFaces(status, coupling, lo, hi)
                    v[:, DRIVING] += c_checked - c
                    c = c_checked
                    continue
            break
    else:
        cand, _, point = np.unravel_index(np.argmax(change), change.shape)
        raise ConvergenceError(f"no convergence in {max_iter} iterations (last |du| = {worst:.3g} m > tol = {tol:g} m)",
                               candidate=int(cand) + candidate_offset, point=int(point))
    u = u_in + r
    u[:, DRIVING] += c
    return np.swapaxes(u, 1, 2), np.swapaxes(c, 1, 2), np.swapaxes(r, 1, 2), iterations
