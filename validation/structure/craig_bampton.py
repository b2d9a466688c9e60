"""Craig-Bampton reduction of the mount's chains: where the chains' own modes begin, and
what a static (Guyan) condensation of the chains onto the payload frame and the nuts
misses.

On the prototype's reduced model (K the tangent at the nominal state, M the mount's
mass) the boundary DOFs are the payload frame's 6 and the three nuts'; the interior DOFs
are the chains' section nodes (4 per chain, 6 DOF each). Chains meet only at the
boundary, so the interior block is block-diagonal by chain and the fixed-interface modes
(K_ii phi = w^2 M_ii phi, frame and nuts held) are each chain's own modes, both ends
clamped. Craig-Bampton keeps the static constraint modes Psi = -K_ii^-1 K_ib and the
lowest n fixed-interface modes Phi: T = [[I, 0], [Psi, Phi]], K_cb = T^T K T,
M_cb = T^T M T. n = 0 is Guyan's static condensation. The chain segments themselves are
one Guyan element each, so modes inside a segment (a leaf's own bending) are not in any
of these: the fixed-interface frequencies are those of the chain as five segments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..prototype.mechanism import FRAME_BODY, INTERIOR_BODIES, N_CHAINS, NUT_BODIES, Prototype

__all__ = ["craig_bampton", "CraigBampton", "mount_boundary", "mount_reductions"]


@dataclass(frozen=True, kw_only=True, eq=False)
class CraigBampton:
    """stiffness, mass (n_b + n, n_b + n): the reduced matrices (boundary DOFs first, then
    the modal coordinates); fixed_interface_Hz (n,); transform T (n_dofs, n_b + n)."""

    stiffness: np.ndarray
    mass: np.ndarray
    fixed_interface_Hz: np.ndarray
    transform: np.ndarray


def craig_bampton(K: np.ndarray, M: np.ndarray, boundary: np.ndarray, n_modes: int) -> CraigBampton:
    """Craig-Bampton reduction (module docstring) of symmetric ``K``, ``M`` (n, n) onto
    the DOFs ``boundary`` plus the lowest ``n_modes`` fixed-interface modes (0: Guyan)."""
    n = K.shape[0]
    boundary = np.asarray(boundary, int)
    interior = np.setdiff1d(np.arange(n), boundary)
    K_ii, K_ib = K[np.ix_(interior, interior)], K[np.ix_(interior, boundary)]
    T = np.zeros((n, len(boundary) + n_modes))
    T[boundary, np.arange(len(boundary))] = 1.0
    T[np.ix_(interior, np.arange(len(boundary)))] = -np.linalg.solve(K_ii, K_ib)
    frequencies = np.zeros(0)
    if n_modes:
        w2, phi = scipy.linalg.eigh(K_ii, M[np.ix_(interior, interior)], subset_by_index=[0, n_modes - 1])
        T[np.ix_(interior, len(boundary) + np.arange(n_modes))] = phi
        frequencies = np.sqrt(np.maximum(w2, 0.0)) / (2 * np.pi)
    K_cb, M_cb = T.T @ K @ T, T.T @ M @ T
    return CraigBampton(stiffness=0.5 * (K_cb + K_cb.T), mass=0.5 * (M_cb + M_cb.T), fixed_interface_Hz=frequencies,
                        transform=T)


def mount_boundary(prototype: Prototype) -> np.ndarray:
    """The frame's 6 and the three nuts' DOFs of the mount."""
    start = prototype.assembly.dof_start
    return np.r_[start[FRAME_BODY] + np.arange(6), [start[b] for b in NUT_BODIES]]


def _frequencies(K: np.ndarray, M: np.ndarray, n: int) -> np.ndarray:
    w2 = scipy.linalg.eigh(K, M, eigvals_only=True, subset_by_index=[0, min(n, K.shape[0]) - 1])
    return np.sqrt(np.maximum(w2, 0.0)) / (2 * np.pi)


def mount_reductions(prototype: Prototype, tangent: np.ndarray, mass: np.ndarray, *, n_show: int = 12,
                     modes_kept: tuple[int, ...] = (0, 6, 12, 24)) -> dict:
    """The mount's lowest ``n_show`` frequencies [Hz]: "full" (every DOF), and for each
    number of fixed-interface modes kept ("guyan" for 0, "craig_bampton_<n>");
    "fixed_interface_Hz": each chain's three lowest own modes, both ends clamped."""
    K = 0.5 * (tangent + tangent.T)
    boundary = mount_boundary(prototype)
    out = {"full": _frequencies(K, mass, n_show).tolist()}
    for n in modes_kept:
        reduced = craig_bampton(K, mass, boundary, n)
        out["guyan" if n == 0 else f"craig_bampton_{n}"] = _frequencies(reduced.stiffness, reduced.mass, n_show).tolist()
    start = prototype.assembly.dof_start
    chains = {}
    for c in range(N_CHAINS):
        dofs = np.concatenate([start[b] + np.arange(6) for b in INTERIOR_BODIES[c]])
        others = np.setdiff1d(np.arange(K.shape[0]), dofs)
        chains[prototype.mechanism.chains[c].name] = craig_bampton(K, mass, others, 3).fixed_interface_Hz.tolist()
    out["fixed_interface_Hz"] = chains
    return out
