"""Generalized symmetric eigenproblems of a held structure: natural modes and buckling.

Both use ARPACK's Lanczos (``scipy.sparse.linalg.eigsh``) on the operator K^-1 (.)
(one sparse LU factorization of K, or of K - shift M), never a dense solve:

* ``natural_modes``: K phi = omega^2 M phi, shift-invert about ``shift`` [rad^2/s^2]
  (default 0: the modes nearest zero frequency converge first). K must be
  non-singular (the structure held) unless ``shift`` is set below zero.
* ``buckling_modes``: K phi = -lambda K_G phi for a prestress whose geometric stiffness
  is K_G (``flexcal.fem.geometric``). Written as -K_G phi = mu K phi with mu = 1/lambda
  and solved for the mu of largest magnitude with K^-1 as the inverse of the "mass" K
  (ARPACK's mode 2): the smallest positive load factors lambda are the largest positive
  mu, the ones Lanczos finds first (a field with tension and compression also has
  negative mu: the load reversed; ask for enough modes to see the positive ones). A sign slip in K_G would turn every factor negative: the function
  reports only positive factors and raises if there are none.

Modes are M-normalized (phi^T M phi = 1) and K-normalized (phi^T K phi = 1) respectively.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .solve import RESIDUAL_LIMIT

__all__ = ["ModalResult", "BucklingResult", "natural_modes", "buckling_modes", "effective_modal_mass"]


@dataclass(frozen=True, kw_only=True, eq=False)
class ModalResult:
    """frequencies (n,) [Hz] ascending; eigenvalues omega^2 (n,) [rad^2/s^2]; modes
    (n_dofs, n) M-normalized."""

    frequencies: np.ndarray
    eigenvalues: np.ndarray
    modes: np.ndarray


@dataclass(frozen=True, kw_only=True, eq=False)
class BucklingResult:
    """factors (n_pos,) [-] ascending, the positive load factors lambda found among the
    n requested; modes (n_dofs, n_pos) K-normalized."""

    factors: np.ndarray
    modes: np.ndarray


def _factorized(A: sp.spmatrix, what: str) -> spla.LinearOperator:
    """x -> A^-1 x by one SuperLU factorization (symmetric MMD ordering)."""
    A = sp.csc_matrix(A)
    try:
        lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A")
    except RuntimeError as error:  # "Factor is exactly singular"
        raise ValueError(f"{what} is singular ({error}): the structure has a free motion; hold it "
                         "(clamp or couple its supports) or use a negative shift") from None
    # SuperLU may factor a singular matrix without error (a round-off pivot) and return
    # garbage: check one solve's residual (the test of flexcal.fem.solve)
    b = np.random.default_rng(0).standard_normal(A.shape[0])
    if not np.linalg.norm(A @ lu.solve(b) - b) <= RESIDUAL_LIMIT * np.linalg.norm(b):
        raise ValueError(f"{what} is singular to working precision: the structure has a free motion; hold it "
                         "(clamp or couple its supports) or use a negative shift")
    return spla.LinearOperator(A.shape, matvec=lu.solve, dtype=float)


def _check_square(name: str, A, n: int | None = None) -> int:
    if A.ndim != 2 or A.shape[0] != A.shape[1] or (n is not None and A.shape[0] != n):
        raise ValueError(f"{name} has shape {A.shape}; expected a square ({n or 'n'}, {n or 'n'}) matrix")
    return A.shape[0]


def natural_modes(K: sp.spmatrix, M: sp.spmatrix, n_modes: int, *, shift: float = 0.0,
                  tol: float = 0.0) -> ModalResult:
    """The ``n_modes`` natural modes of K phi = omega^2 M phi nearest ``shift``
    [rad^2/s^2] (stiffness K [N/m], mass M [kg], same DOFs; both symmetric, M positive
    definite on the DOFs). ``tol``: ARPACK's relative accuracy (0: machine precision)."""
    n = _check_square("K", K)
    _check_square("M", M, n)
    if not 1 <= n_modes < n:
        raise ValueError(f"n_modes={n_modes} must be in [1, {n - 1}] (eigsh needs fewer modes than DOFs)")
    op = _factorized(sp.csc_matrix(K) - shift * sp.csc_matrix(M), "K - shift M")
    values, vectors = spla.eigsh(sp.csr_matrix(K), k=n_modes, M=sp.csr_matrix(M), sigma=shift, which="LM",
                                 OPinv=op, tol=tol)
    order = np.argsort(values)
    values, vectors = values[order], vectors[:, order]
    frequencies = np.sqrt(np.clip(values, 0.0, None)) / (2.0 * np.pi)
    return ModalResult(frequencies=frequencies, eigenvalues=values, modes=vectors)


def buckling_modes(K: sp.spmatrix, K_G: sp.spmatrix, n_modes: int = 1, *, tol: float = 0.0) -> BucklingResult:
    """Smallest positive load factors lambda of (K + lambda K_G) phi = 0 (K [N/m]
    symmetric positive definite: the structure held; K_G [N/m] the geometric stiffness of
    the reference prestress). The ``n_modes`` eigenpairs of largest |1/lambda| are
    computed; the positive ones are returned. Raises ``ValueError`` if none is positive (the prestress cannot buckle the
    structure: a tension field, or a sign slip in K_G)."""
    n = _check_square("K", K)
    _check_square("K_G", K_G, n)
    if not 1 <= n_modes < n:
        raise ValueError(f"n_modes={n_modes} must be in [1, {n - 1}]")
    K = sp.csr_matrix(K)
    Kinv = _factorized(K, "K")
    mu, vectors = spla.eigsh(-sp.csr_matrix(K_G), k=n_modes, M=K, Minv=Kinv, which="LM", tol=tol)
    # mu of a rank-deficient K_G cluster at zero; "positive" means above round-off of the
    # largest |mu| (a factor beyond 1e10 x the smallest is not a buckling load)
    positive = mu > 1e-10 * np.max(np.abs(mu))
    if not positive.any():
        raise ValueError("no positive buckling factor: the prestress does not compress the structure anywhere it "
                         "can buckle (check the load's sign and the sign convention of K_G: tension positive)")
    factors = 1.0 / mu[positive]
    order = np.argsort(factors)
    return BucklingResult(factors=factors[order], modes=vectors[:, positive][:, order])


def effective_modal_mass(M: np.ndarray | sp.spmatrix, modes: np.ndarray, influence: np.ndarray) -> np.ndarray:
    """Effective modal masses (n_modes, n_directions) [kg or kg m^2] of M-normalized
    ``modes`` (n_dofs, n_modes) for rigid ``influence`` vectors (n_dofs, n_directions)
    (a unit translation or rotation of the supports): m_eff = (phi^T M r)^2. Summed over
    all modes they give r^T M r, the total mass (or inertia) moved."""
    participation = modes.T @ (M @ influence)
    return participation**2
