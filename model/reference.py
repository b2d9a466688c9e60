"""A plain per-point implementation of Eq. 8: the benchmark baseline and a test oracle.

Same physics as ``forward``, written the straightforward way: for each candidate and
point, assemble the 6x6 frame stiffness and solve it with ``numpy.linalg.solve`` for every
equilibrium that is needed, iterate the parasitic term, and find the clearance by its
definition (Eq. 6-7 as read in docs/model.md): ``fx_i`` from the axial load with chain i's
clearance shut and the others as they are, ``C_i = d_i clip(mu_i fx_i, 0, CL_i)`` for all
three chains at once, by checking the 27 combinations of "shut / in the gap / at the far
flank". It shares only the per-candidate chain matrices (``MechanismMatrices``) with the
fast engines, not their algebra (no Schur complements, coupling matrices or active sets).
"""

from __future__ import annotations

import itertools

import numpy as np

from .assembly import MechanismMatrices, payload_wrench
from .clearance import ConvergenceError
from .parameters import DRIVING

__all__ = ["reference_point", "reference_forward"]

_STATES = list(itertools.product(("shut", "gap", "flank"), repeat=3))


def _equilibrium(m: MechanismMatrices, cand: int, u: np.ndarray, wrench: np.ndarray):
    """X_C (6,) and axial loads N (6,) for axial A-end displacements u (6,), one candidate."""
    k, j = m.chain_stiffness[cand], m.frame_transform[cand]
    k_cc = np.zeros((6, 6))
    rhs = wrench.copy()
    for i in range(6):
        k_cc += j[i].T @ k[i] @ j[i]
        rhs += j[i].T @ k[i][:, 0] * u[i]
    pose = np.linalg.solve(k_cc, rhs)
    loads = np.array([k[i][0] @ (j[i] @ pose) - k[i][0, 0] * u[i] for i in range(6)])
    return pose, loads


def _clearance(m, cand, u_other, d, wrench):
    """C (3,) of Eq. 6-7 for the A-end displacements without clearance ``u_other`` (6,)."""
    mu, limit = m.mu[cand], m.clearance[cand]
    if not np.any((limit > 0) & (mu > 0)):
        return np.zeros(3)
    # axial loads are affine in C: N(C) = N0 + A C, from four equilibria
    base = _equilibrium(m, cand, u_other, wrench)[1][DRIVING]
    gain = np.zeros((3, 3))
    for j in range(3):
        u = u_other.copy()
        u[3 + j] += 1e-3
        gain[:, j] = (_equilibrium(m, cand, u, wrench)[1][DRIVING] - base) / 1e-3
    stiffness = -np.diag(gain)  # a chain's own nut stiffness s_i (dN_i/dC_i = -s_i)

    def release(c):  # fx_i with chain i's clearance shut, the others at c
        out = np.zeros(3)
        for i in range(3):
            shut = c.copy()
            shut[i] = 0.0
            out[i] = d[i] * (base[i] + gain[i] @ shut) / stiffness[i]
        return out

    best, best_violation = None, np.inf
    for states in _STATES:
        # y_i = d_i C_i: 0 (shut), CL (flank), or mu fx (gap): linear equations in the gap ones
        gap = [i for i in range(3) if states[i] == "gap"]
        c = np.array([0.0 if s != "flank" else d[i] * limit[i] for i, s in enumerate(states)])
        if gap:
            # C_g = d_g mu_g fx_g(C) for g in gap: fx is affine in C -> solve
            mat = np.zeros((len(gap), len(gap)))
            vec = np.zeros(len(gap))
            for row, g in enumerate(gap):
                coeff = mu[g] * (gain[g] / stiffness[g])  # d_g^2 = 1
                coeff[g] = 0.0
                vec[row] = mu[g] * base[g] / stiffness[g] + sum(coeff[j] * c[j] for j in range(3) if j not in gap)
                for col, h in enumerate(gap):
                    mat[row, col] = (1.0 if g == h else 0.0) - coeff[h]
            c[gap] = np.linalg.solve(mat, vec)
        target = np.clip(mu * release(c), 0.0, limit)
        violation = np.max(np.abs(d * c - target))
        if violation < best_violation:
            best, best_violation = c, violation
    if best_violation > 1e-9:
        raise ConvergenceError(f"reference clearance: no consistent combination (violation {best_violation:.3g} m)",
                               candidate=cand)
    return best


def reference_point(m: MechanismMatrices, cand: int, inputs: np.ndarray, directions: np.ndarray, wrench: np.ndarray,
                    *, parasitic: bool = True, clearance: bool = True, tol: float = 1e-13, max_iter: int = 100):
    """One candidate, one point: (pose (6,), loads (6,), C (3,), r (6,)) [SI]."""
    u_in = np.zeros(6)
    u_in[3:] = inputs + m.initial_position[cand]
    r, c = np.zeros(6), np.zeros(3)
    for _ in range(max_iter):
        u = u_in + r
        c_new = _clearance(m, cand, u, directions, wrench) if clearance else np.zeros(3)
        u[3:] += c_new
        pose, loads = _equilibrium(m, cand, u, wrench)
        if not parasitic:
            return pose, loads, c_new, r
        rows = m.parasitic_rows[cand]
        lateral = rows @ pose
        r_new = -m.parasitic_coefficient[cand] * (lateral[:6] ** 2 + lateral[6:] ** 2)
        change = max(np.max(np.abs(r_new - r)), np.max(np.abs(c_new - c)))
        r, c = r_new, c_new
        if change <= tol:
            u = u_in + r
            c = _clearance(m, cand, u, directions, wrench) if clearance else np.zeros(3)
            u[3:] += c
            pose, loads = _equilibrium(m, cand, u, wrench)
            return pose, loads, c, r
    raise ConvergenceError("reference iteration did not converge", candidate=cand)


def reference_forward(m: MechanismMatrices, mech, inputs: np.ndarray, directions: np.ndarray, *,
                      parasitic: bool = True, clearance: bool = True, candidates=None):
    """Loop ``reference_point`` over candidates and points: pose (n_c, n_p, 6), C (n_c, n_p, 3)."""
    wrench = payload_wrench(mech)
    cands = range(m.n_candidates) if candidates is None else candidates
    pose = np.zeros((len(cands), inputs.shape[0], 6))
    clear = np.zeros((len(cands), inputs.shape[0], 3))
    for a, cand in enumerate(cands):
        for p in range(inputs.shape[0]):
            pose[a, p], _, clear[a, p], _ = reference_point(m, cand, inputs[p], directions[p], wrench,
                                                            parasitic=parasitic, clearance=clearance)
    return pose, clear
