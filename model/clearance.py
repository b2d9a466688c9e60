"""Paper Eq. 6-7: the equivalent clearance of the three driving chains, solved exactly.

Our reading (docs/model.md "Clearance"): after a move in direction d_i (+1 towards B) the
nut of driving chain i sits on its driving flank. Its axial load N_i (tension > 0) would be
released by a nut displacement ``N_i / s_i`` with the rest of the mechanism re-equilibrating
(``s_i = k_i - g_i^T K_CC^-1 g_i``, the Schur-complement stiffness seen from the nut), so
``fx_i = d_i N_i(C_i = 0) / s_i`` is > 0 when the load pulls the nut off the driving flank
into the gap. Eq. 7 with ``ul = CL``: ``C_i = d_i clip(mu_i fx_i, 0, CL_i)``.

The chains couple: N_i depends on the other C_j through ``m_ij = g_i^T K_CC^-1 g_j``. With
``a_i = mu_i N_i(C = 0) / s_i`` [m] (all clearances shut) and ``B_ij = mu_i m_ij / s_i``
(i != j, B_ii = 0), Eq. 7 for all three chains reads, in the signed clearance C itself,

    C = clip(a + B C, lo, hi),   [lo_i, hi_i] = [0, CL_i] if d_i = +1, [-CL_i, 0] if d_i = -1,

the optimality conditions of a box-constrained QP with matrix
``M = diag(s/mu) (I - B) = diag(s/mu + m_ii) - m``; ``M`` is symmetric positive definite
(``diag(k) - m`` is the Schur complement of the positive definite strain energy of frame
and nuts; ``mu <= 1`` only adds to the diagonal), so the solution is unique and continuous
in ``a``. The travel directions only choose the side of each box; the matrices are per
candidate.

``solve_clearance`` finds it exactly: a primal-dual active-set (semismooth Newton) sweep
classifies each chain as at ``lo``, free, or at ``hi`` from ``z = a + B C`` and re-solves
the free ones (``(I - B_FF) C_F = a_F + B_F,clamped C_clamped``) until no status changes;
it is warm-started from the previous statuses, so inside the parasitic iteration one sweep
usually confirms the state. Points still changing after ``MAX_SWEEPS`` (active-set methods
can cycle on non-M-matrices) are solved by enumerating all 27 faces of the box and taking
the one that satisfies the conditions (KKT), in which case a ``ConvergenceError`` is raised
only if no face does to ``HARD_TOLERANCE``.
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["solve_clearance", "clearance_coupling", "FixedFaces", "ConvergenceError", "LOWER", "FREE", "UPPER",
           "MAX_SWEEPS"]

LOWER, FREE, UPPER = 0, 1, 2
MAX_SWEEPS = 8
ABSOLUTE_TOLERANCE = 1e-13  # [m] KKT slack accepted for a face (0.1 pm; roundoff ~1e-16 * |a|)
RELATIVE_TOLERANCE = 1e-13  # [-] of max |a| (a up to ~0.1 m: fx = N/s)
HARD_TOLERANCE = 1e-9  # [m] if even the best face violates more, the solve failed
_FACES = np.array(list(itertools.product((LOWER, FREE, UPPER), repeat=3)), dtype=np.int8)  # (27, 3)


class ConvergenceError(RuntimeError):
    """The model did not converge (or a sub-solve failed) at a named candidate and point.

    Attributes ``candidate``, ``point`` (indices, or None) and ``reason``.
    """

    def __init__(self, reason: str, candidate: int | None = None, point: int | None = None):
        where = []
        if candidate is not None:
            where.append(f"candidate {candidate}")
        if point is not None:
            where.append(f"point {point}")
        super().__init__(f"{', '.join(where) or 'model'}: {reason}")
        self.candidate, self.point, self.reason = candidate, point, reason


def clearance_coupling(coupling: np.ndarray, nut_stiffness: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """``B_ij = mu_i m_ij / s_i`` (i != j), zero diagonal, (n_c, 3, 3) [-].

    coupling m of the driving chains (n_c, 3, 3) [N/m], nut_stiffness s (n_c, 3) [N/m], mu (n_c, 3).
    """
    return (mu / nut_stiffness)[:, :, None] * coupling * (1.0 - np.eye(3))


def _inverse_3x3(m: np.ndarray) -> np.ndarray:
    """Batched 3x3 inverse by the adjugate (..., 3, 3)."""
    a, b, c = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    d, e, f = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    g, h, i = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    co = np.stack([e * i - f * h, c * h - b * i, b * f - c * e,
                   f * g - d * i, a * i - c * g, c * d - a * f,
                   d * h - e * g, b * g - a * h, a * e - b * d], axis=-1).reshape(m.shape)
    det = a * co[..., 0, 0] + b * co[..., 1, 0] + c * co[..., 2, 0]
    return co / det[..., None, None]


def _tolerance(a: np.ndarray, axis: int) -> np.ndarray:
    return ABSOLUTE_TOLERANCE + RELATIVE_TOLERANCE * np.max(np.abs(a), axis=axis, keepdims=True)


def _classify(z: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.where(z <= lo, LOWER, np.where(z >= hi, UPPER, FREE)).astype(np.int8)


def _face_values(status, a, b, lo, hi):
    """C on the faces ``status`` (m, 3) for points with a (m, 3), b (m, 3, 3), lo/hi (m, 3)."""
    free = status == FREE
    clamped = np.where(status == LOWER, lo, np.where(status == UPPER, hi, 0.0))
    rhs = a + (b @ clamped[..., None])[..., 0]
    mask = free[..., :, None] & free[..., None, :]
    inverse = _inverse_3x3(np.eye(3) - np.where(mask, b, 0.0))
    solved = (inverse @ np.where(free, rhs, 0.0)[..., None])[..., 0]
    return np.where(free, solved, clamped)


def _enumerate(a, b, lo, hi):
    """Exact solve of a few points by checking all 27 faces: C (m, 3) and the best slack (m,)."""
    n = a.shape[0]
    best = np.full(n, np.inf)
    out = np.zeros_like(a)
    tol = _tolerance(a, axis=1)[:, 0]
    for face in _FACES:
        status = np.broadcast_to(face, a.shape)
        c = _face_values(status, a, b, lo, hi)
        z = a + (b @ c[..., None])[..., 0]
        slack = np.where(status == FREE, np.maximum(lo - c, c - hi),
                         np.where(status == LOWER, z - lo, hi - z))
        worst = np.max(slack, axis=1)
        better = worst < best
        out[better], best[better] = c[better], worst[better]
        if np.all(best <= tol):
            break
    return out, best - tol


class FixedFaces:
    """``C`` as an affine function of ``a`` while the chain statuses stay fixed.

    Inside the parasitic iteration ``a`` moves by ~1e-7 of itself per step, so the statuses
    found by ``solve_clearance`` are held and only re-checked (by ``solve_clearance``) once
    the iteration has converged. status (n_c, 3, n_p) int8; coupling B (n_c, 3, 3); lo, hi
    (n_c, 3, n_p) [m].
    """

    def __init__(self, status: np.ndarray, coupling: np.ndarray, lo: np.ndarray, hi: np.ndarray):
        self.status = status
        self.free = status == FREE
        self.clamped = np.where(status == LOWER, lo, np.where(status == UPPER, hi, 0.0))
        self.offset = coupling @ self.clamped
        multi = np.count_nonzero(self.free, axis=1) > 1
        self.multi_c, self.multi_p = np.nonzero(multi)
        if self.multi_c.size:
            free = self.free[self.multi_c, :, self.multi_p]
            b = coupling[self.multi_c]
            inverse = _inverse_3x3(np.eye(3) - np.where(free[..., :, None] & free[..., None, :], b, 0.0))
            self.multi_inverse = inverse * free[..., :, None] * free[..., None, :]

    def __call__(self, a: np.ndarray) -> np.ndarray:
        rhs = a + self.offset
        c = np.where(self.free, rhs, self.clamped)  # exact where at most one chain is free (B_ii = 0)
        if self.multi_c.size:
            solved = (self.multi_inverse @ rhs[self.multi_c, :, self.multi_p][..., None])[..., 0]
            c[self.multi_c, :, self.multi_p] = np.where(self.free[self.multi_c, :, self.multi_p], solved,
                                                        c[self.multi_c, :, self.multi_p])
        return c


def solve_clearance(a: np.ndarray, coupling: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                    status: np.ndarray | None = None, candidate_offset: int = 0):
    """Solve ``C = clip(a + B C, lo, hi)`` at every point.

    a (n_c, 3, n_p) [m]; coupling B (n_c, 3, 3) (``clearance_coupling``); lo, hi
    (n_c, 3, n_p) [m] the box of each chain (one of them 0); status (n_c, 3, n_p) int8 warm
    start (LOWER/FREE/UPPER) or None. Returns (C (n_c, 3, n_p) [m], status).
    """
    status = _classify(a, lo, hi) if status is None else status
    tol = _tolerance(a, axis=1)
    for _ in range(MAX_SWEEPS):
        free = status == FREE
        clamped = np.where(status == LOWER, lo, np.where(status == UPPER, hi, 0.0))
        rhs = a + coupling @ clamped
        c = np.where(free, rhs, clamped)  # exact where at most one chain is free (B_ii = 0)
        multi = np.count_nonzero(free, axis=1) > 1  # (n_c, n_p)
        if np.any(multi):
            ci, pi = np.nonzero(multi)
            c[ci, :, pi] = _face_values(status[ci, :, pi], a[ci, :, pi], coupling[ci], lo[ci, :, pi], hi[ci, :, pi])
        z = a + coupling @ c
        # keep a status while its condition holds to the tolerance (no flip-flop at a kink)
        keep = np.where(free, (c >= lo - tol) & (c <= hi + tol),
                        np.where(status == LOWER, z <= lo + tol, z >= hi - tol))
        if np.all(keep):
            return np.clip(c, lo, hi), status
        status = np.where(keep, status, _classify(np.where(free, c, z), lo, hi))
    # cycling or slow points: exact enumeration
    ci, pi = np.nonzero(~np.all(keep, axis=1))
    exact, violation = _enumerate(a[ci, :, pi], coupling[ci], lo[ci, :, pi], hi[ci, :, pi])
    if np.any(violation > HARD_TOLERANCE):
        k = int(np.argmax(violation))
        raise ConvergenceError(f"clearance solve found no consistent state (best violation {violation[k]:.3g} m)",
                               candidate=int(ci[k]) + candidate_offset, point=int(pi[k]))
    c[ci, :, pi] = exact
    z = a + coupling @ c
    inside = (c > lo + tol) & (c < hi - tol)
    status = np.where(inside, FREE, _classify(z, lo, hi)).astype(np.int8)
    return np.clip(c, lo, hi), status
