"""Sparse symmetric positive-definite solves with several right-hand sides.

``solve_spd(K, rhs, method=...)`` factorizes once and solves every column of ``rhs``
with that factorization (condensation needs 6 or 12 right-hand sides).

Methods (measured on hinge-size problems, see docs/fem.md):

* ``"pardiso"`` -- Intel MKL PARDISO through pypardiso, symmetric positive-definite
  mode (mtype 2, upper triangle only): the fastest and the default.
* ``"splu"`` -- scipy SuperLU with the symmetric (MMD on A^T + A) ordering.
* ``"spsolve"`` -- ``scipy.sparse.linalg.spsolve`` as users call it (COLAMD ordering);
  the baseline.
* ``"amg"`` -- conjugate gradients preconditioned by pyamg smoothed aggregation with the
  rigid-body modes as near-null space (pass ``near_null_space``); iterative, one solve
  per right-hand side, relative residual ``rtol``.

``"auto"`` is pardiso when pypardiso loads, else splu.
"""

from __future__ import annotations

import contextlib
import ctypes
import glob
import os
import sys
import threading
from collections.abc import Iterator

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["SOLVERS", "pardiso_available", "solve_spd", "solver_threads", "one_thread", "inverse_quadratic_form",
           "SpdFactors", "spd_factors"]

SOLVERS = ("auto", "pardiso", "splu", "spsolve", "amg")
RESIDUAL_LIMIT = 1e-6
"""Largest accepted ||K x - b|| / ||b|| per column (AMG stops at rtol <= 1e-10 anyway)."""
RESIDUAL_BLOCK = 32
"""Right-hand sides whose residual is checked at once (bounds the check's temporaries)."""


_PER_THREAD = threading.local()  # a PARDISO handle and MKL thread count of each thread
PARDISO_OUT_OF_MEMORY = -2  # MKL PARDISO error code "not enough memory" (-4 is a zero pivot)


def _point_pypardiso_at_mkl() -> None:
    """pypardiso looks for MKL's runtime with a recursive glob over the environment on
    every handle it makes (~0.5 s each, twice per process). When the runtime sits in
    ``<prefix>/lib`` (the pip wheel's place) say so through pypardiso's own variable."""
    if "PYPARDISO_MKL_RT" in os.environ:
        return
    found = sorted(glob.glob(os.path.join(sys.prefix, "lib", "libmkl_rt.so*")), key=len)
    if found:
        os.environ["PYPARDISO_MKL_RT"] = found[0]


def _ask_mkl_for_reproducible_results() -> None:
    """MKL's conditional numerical reproducibility (``MKL_CBWR=AUTO``), unless the user
    chose a mode: PARDISO's threaded factorization otherwise sums in an order that
    changes from call to call. Measured on the 216k-DOF Laplacian of
    tests/test_fem_solve.py and on chain D1 at 2 elements through (~145k DOF, 2 threads):
    4 solves, 4 different last bits (1e-11 relative on the chain's compliance diagonal)
    before; bit-identical after, at the same speed (3.2-3.8 s vs 3.3-3.5 s a chain solve).
    MKL reads it once, when it starts in the process, so this runs before pypardiso
    loads it. The promise is MKL's: the same bits for the same thread count and
    instruction set; another thread count gives other last bits (measured: 1 thread
    differs from 2 at ~1e-11). ``MKL_CBWR=COMPATIBLE`` would hold across machines too,
    at 1.45x the time (measured 4.96-4.99 s vs 3.3-3.5 s on chain D1); not chosen."""
    os.environ.setdefault("MKL_CBWR", "AUTO")


@contextlib.contextmanager
def solver_threads(n_threads: int) -> Iterator[None]:
    """PARDISO solves of the calling thread, inside the block, on ``n_threads`` MKL
    threads (``MKL_Set_Num_Threads_Local``: this thread only; MKL's own count elsewhere).
    For jobs run side by side in threads of one process, each owning one core
    (``flexcal.validation.executor``, the FEM segment builds)."""
    if isinstance(n_threads, bool) or not isinstance(n_threads, int) or n_threads < 1:
        raise ValueError(f"n_threads={n_threads!r} must be an integer >= 1")
    previous = getattr(_PER_THREAD, "mkl_threads", 0)
    _PER_THREAD.mkl_threads = n_threads
    try:
        with _openmp_threads(n_threads):
            yield
    finally:
        _PER_THREAD.mkl_threads = previous


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """Inside the block, this thread's PARDISO on one MKL thread (``solver_threads(1)``) and, on
    the main thread, the process's BLAS pools on one thread (threadpoolctl), so that what is
    computed does not depend on the machine's cores or on how many jobs shared them: MKL's
    PARDISO and OpenBLAS give other last bits on another thread count (a tied chain alone on both
    cores against one of two side by side: 1.4e-13 relative; with both at one thread, the same
    bits). ``fem.cache.cached`` computes every entry inside it (docs/scale.md, "Issue 26, session
    36"). Another thread's jobs run inside their executor's batch, which holds the pools at one
    from the thread that started it (``validation.prototype.fem_provider.build_missing``):
    OpenBLAS takes its count from there (measured, threadpoolctl 3 on OpenBLAS 0.3.30: a limit
    set on another thread after the main thread set one did not show)."""
    with solver_threads(1), (_blas_on_one_thread() if threading.current_thread() is threading.main_thread()
                             else contextlib.nullcontext()):
        yield


def _blas_on_one_thread():
    """threadpoolctl's limit of every loaded BLAS to one thread, after loading scipy's own
    OpenBLAS and MKL (a library loaded after the limit keeps its own count)."""
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    pardiso_available()
    return threadpool_limits(1, user_api="blas")


def _openmp_threads(n_threads: int):
    """This thread's OpenMP teams held at ``n_threads`` inside the block (``omp_set_num_threads``
    through threadpoolctl: OpenMP's count is the calling thread's own), with MKL's runtime
    loaded first so that its OpenMP library is among those limited. PARDISO's factorization
    opens teams of OpenMP's count, not of ``MKL_Set_Num_Threads_Local``'s: inside
    ``solver_threads(1)`` a second thread ran beside it and then spun for OpenMP's block time
    (KMP_BLOCKTIME, 200 ms) after every region, 1.6x the CPU for the same wall alone and the
    other job's core taken in threaded builds (docs/scale.md, "Issue 26, session 31")."""
    from threadpoolctl import threadpool_limits

    pardiso_available()  # loads MKL and its OpenMP runtime, if there is one
    return threadpool_limits(n_threads, user_api="openmp")


def _pardiso_solver():
    """This thread's PARDISO handle (MKL's PARDISO is thread-safe for distinct handles;
    ``_new_pardiso_solver``), with MKL set to this thread's ``solver_threads`` count (0,
    outside such a block: the process's count)."""
    solver = getattr(_PER_THREAD, "pardiso", None)
    if solver is None:
        solver = _PER_THREAD.pardiso = _new_pardiso_solver()
    solver.libmkl.MKL_Set_Num_Threads_Local(getattr(_PER_THREAD, "mkl_threads", 0))
    return solver


def _new_pardiso_solver():
    """A PARDISO handle in SPD mode (mtype 2), its factors freed after every
    solve. Parameters (0-based iparm): [1] = 2 nested-dissection ordering (METIS);
    [7] = 0 iterative-refinement steps: MKL's default of 2 made the condensed 6x6 less
    accurate here (4.6e-11 vs 5.7e-12 relative to SuperLU on a 13k-DOF hinge) and the
    solve phase 2-3x slower; [9] = 8 pivot perturbation 1e-8 (inactive for SPD);
    [17] = -1 report the factor size; [36] = -80 let PARDISO regroup the CSR matrix into
    variable-size blocks (the 3x3 node blocks of elasticity): 25 % less CPU time on a
    54k-DOF hinge, 5 % on 136k, same result to 1e-11 (inactive since [23] = 1: the
    two-level factorization reads the scalar CSR; kept for a return to [23] = 0);
    [23] = 1 the two-level factorization: 15-21 % less CPU time in the numeric
    factorization of the prototype's 70k-80k-DOF leaf segments on one MKL thread
    (L1 [0, m1] 2.98 s against 3.53 s, D1 [m1, s0] 2.17 s against 2.75 s, medians of 4
    alternating, load 6), ~40 % on a 17k-DOF one, and a faster analysis; the
    condensed 12 x 12 moves by <= 1.8e-13 relative, the same bits on repeated runs,
    one thread against two 3.8e-14 (docs/scale.md, session 17)."""
    _point_pypardiso_at_mkl()
    _ask_mkl_for_reproducible_results()
    import pypardiso

    solver = pypardiso.PyPardisoSolver(mtype=2)
    set_local = solver.libmkl.MKL_Set_Num_Threads_Local  # the C entry (by value); the lower-case one is Fortran's
    set_local.argtypes, set_local.restype = [ctypes.c_int], ctypes.c_int
    solver.iparm[:] = 0
    solver.iparm[0] = 1  # use the values below, defaults for the rest
    solver.iparm[1] = 2
    solver.iparm[7] = 0
    solver.iparm[9] = 8
    solver.iparm[17] = -1
    solver.iparm[23] = 1
    solver.iparm[36] = -80
    return solver


def pardiso_available() -> bool:
    """True if pypardiso and its MKL runtime load."""
    try:
        _pardiso_solver()
    except Exception:  # ImportError, or MKL runtime missing
        return False
    return True


@contextlib.contextmanager
def _pardiso_errors(n_dofs: int) -> Iterator[None]:
    """PARDISO's failures inside the block as the errors a user can act on; the calling
    thread's handle freed after (``_pardiso_solver``)."""
    import pypardiso

    try:
        yield
    except pypardiso.pardiso_wrapper.PyPardisoError as error:
        raise _pardiso_failure(error, n_dofs) from error
    finally:
        _pardiso_solver().free_memory(everything=True)


def _pardiso_failure(error, n_dofs: int) -> Exception:
    """The error a user can act on for PARDISO's ``error`` on an ``n_dofs`` system."""
    if getattr(error, "value", None) == PARDISO_OUT_OF_MEMORY:
        return RuntimeError(f"PARDISO failed ({error}): not enough memory for the factorization of {n_dofs} DOF "
                            "(a coarser mesh or a machine with more memory)")
    return ValueError(f"PARDISO failed ({error}); K is probably not positive definite: a body part is not held "
                      "(check the clamps and couplings)")


def _upper(K: sp.csr_matrix, upper_triangle: bool) -> sp.csr_matrix:
    """The upper triangle of K with sorted indices (mtype 2 reads the upper triangle only)."""
    upper = K if upper_triangle else sp.triu(K, format="csr")
    upper.sort_indices()
    return upper


def _solve_pardiso(K: sp.csr_matrix, rhs: np.ndarray, upper_triangle: bool = False) -> np.ndarray:
    upper = _upper(K, upper_triangle)
    with _pardiso_errors(K.shape[0]):
        # one call, phase 13 (analysis, factorization, solve): pypardiso's solve on a handle
        # that holds no factorization (each solve frees it below). The same bits as
        # factorize (phase 12) then solve (33), without the copy of the matrix factorize kept
        # to recognise it and the second call's index conversions (~0.05 s a 100k-DOF solve)
        x = _pardiso_solver().solve(upper, np.asfortranarray(rhs))
    return x


def _solve_splu(K: sp.csr_matrix, rhs: np.ndarray, permc_spec: str) -> np.ndarray:
    try:
        lu = spla.splu(K.tocsc(), permc_spec=permc_spec)
    except RuntimeError as error:
        raise ValueError(f"SuperLU failed ({error}); K is singular: a body part is not held") from error
    return lu.solve(rhs)


def _solve_amg(K: sp.csr_matrix, rhs: np.ndarray, near_null_space: np.ndarray | None, rtol: float) -> np.ndarray:
    import pyamg

    if near_null_space is None:
        raise ValueError("method='amg' needs near_null_space (n, 6): the rigid-body modes of the reduced DOFs")
    ml = pyamg.smoothed_aggregation_solver(K, B=np.asarray(near_null_space, float), symmetry="hermitian")
    M = ml.aspreconditioner(cycle="V")
    out = np.empty_like(rhs)
    for k in range(rhs.shape[1]):
        b = rhs[:, k]
        if not np.any(b):
            out[:, k] = 0.0
            continue
        x, info = spla.cg(K, b, rtol=rtol, atol=0.0, M=M, maxiter=2000)
        if info != 0:
            raise ValueError(f"AMG-preconditioned CG did not reach rtol={rtol} in 2000 iterations; use a direct method")
        out[:, k] = x
    return out


def solve_spd(
    K: sp.spmatrix,
    rhs: np.ndarray,
    *,
    method: str = "auto",
    near_null_space: np.ndarray | None = None,
    rtol: float = 1e-10,
    upper_triangle: bool = False,
) -> np.ndarray:
    """Solve K X = rhs for symmetric positive-definite sparse K (n, n).

    rhs (n,) or (n, k); returns X of the same shape. One factorization serves all k
    columns (direct methods). ``rtol``: relative residual of the iterative ``"amg"``
    method only. ``upper_triangle``: K holds only the upper triangle of the symmetric
    matrix, with its diagonal (what PARDISO reads; the other methods get it mirrored).
    Raises ``ValueError`` for an unknown method or a singular K."""
    if method not in SOLVERS:
        raise ValueError(f"unknown solver method {method!r}; choose one of {', '.join(SOLVERS)}")
    K = sp.csr_matrix(K, dtype=float)
    if K.shape[0] != K.shape[1]:
        raise ValueError(f"K must be square, got {K.shape}")
    upper = None
    if upper_triangle:
        upper = K
        upper.sort_indices()
        starts = upper.indptr[:-1]
        filled = np.diff(upper.indptr) > 0
        if np.any(upper.indices[starts[filled]] < np.flatnonzero(filled)):
            raise ValueError("upper_triangle=True: K has entries below the diagonal")
    rhs = np.asarray(rhs, float)
    single = rhs.ndim == 1
    B = rhs[:, None] if single else rhs
    if B.shape[0] != K.shape[0]:
        raise ValueError(f"rhs has {B.shape[0]} rows; K has {K.shape[0]}")
    if method == "auto":
        method = "pardiso" if pardiso_available() else "splu"
    if upper is not None and method != "pardiso":
        K = (upper + sp.triu(upper, k=1, format="csr").T).tocsr()  # the symmetric matrix
    if method == "pardiso":
        X = _solve_pardiso(K, B, upper_triangle=upper is not None)
    elif method == "splu":
        X = _solve_splu(K, B, "MMD_AT_PLUS_A")
    elif method == "spsolve":
        X = spla.spsolve(K.tocsc(), B)
        X = X.reshape(B.shape)
    else:
        X = _solve_amg(K, B, near_null_space, rtol)
    if not np.isfinite(X).all():
        raise ValueError("the solution contains NaN or inf: K is singular (a body part is not held)")
    residual = np.empty(B.shape[1])
    # column by column in blocks: the products' temporaries stay a block's size (a 260k-DOF
    # system with 285 right-hand sides held 3 GB of them at once); each column's sums are the same
    for start in range(0, B.shape[1], RESIDUAL_BLOCK):
        columns = slice(start, start + RESIDUAL_BLOCK)
        X_b = X[:, columns]
        if upper is not None and method == "pardiso":  # K X of the symmetric matrix from its upper triangle
            product = upper @ X_b + upper.T @ X_b - upper.diagonal()[:, None] * X_b
        else:
            product = K @ X_b
        residual[columns] = np.linalg.norm(product - B[:, columns], axis=0)
    scale = np.linalg.norm(B, axis=0)
    # A direct solve of a regular K leaves ||r|| <~ eps cond(K) ||b|| (measured 3e-9 to
    # 6e-9 on a 13k-DOF coupled hinge system); SuperLU on a singular K (a free body)
    # returns garbage with ||r|| ~ 10 ||b|| and no error.
    if np.any(residual > RESIDUAL_LIMIT * np.where(scale > 0, scale, 1.0)):
        raise ValueError(
            f"the {method} solve left a relative residual of {np.max(residual / np.where(scale > 0, scale, 1.0)):.2g}: "
            "K is singular or nearly so (a body part is not held, or a coupling face was missed)"
        )
    return X[:, 0] if single else X



def _forward_gram(solver, upper: sp.csr_matrix, B: np.ndarray) -> np.ndarray:
    """B^T K^-1 B from the factors the PARDISO handle ``solver`` holds of K (its upper triangle
    ``upper``): the forward substitution Y = L^-1 P B only, M = Y^T Y; checked on one probe
    column (``inverse_quadratic_form``)."""
    probe = B.sum(axis=1)
    solver.set_phase(331)  # forward substitution only
    Y = solver._call_pardiso(upper, np.asfortranarray(B))
    solver.set_phase(33)
    x = solver._call_pardiso(upper, np.asfortranarray(probe[:, None]))[:, 0]
    if not (np.isfinite(Y).all() and np.isfinite(x).all()):
        raise ValueError("the solution contains NaN or inf: K is singular (a body part is not held)")
    residual = np.linalg.norm(upper @ x + upper.T @ x - upper.diagonal() * x - probe)
    M = Y.T @ Y
    energy, from_forward = float(probe @ x), float(M.sum())
    # the probe's residual as solve_spd's bound (RESIDUAL_LIMIT); its energy b^T K^-1 b two ways:
    # forward-only against a full solve, equal to ~1e-15 on a regular K (measured 2e-16 to 5e-16
    # of the largest entry on the tied chains' classes), 1e-8 leaves room for cond(K) ~ 1e7
    if residual > RESIDUAL_LIMIT * np.linalg.norm(probe) or abs(energy - from_forward) > 1e-8 * abs(energy):
        raise ValueError("the forward-only condensation failed its probe: K is singular or nearly so "
                         "(a body part is not held, or a coupling face was missed)")
    return 0.5 * (M + M.T)


def inverse_quadratic_form(K: sp.spmatrix, B: np.ndarray, *, upper_triangle: bool = False) -> np.ndarray:
    """B^T K^-1 B (k, k), symmetric, for symmetric positive-definite sparse K (n, n) and B (n, k):
    what a condensation needs of K^-1 B (``flexcal.fem.condense.mirrored_coupled_stiffness``).

    With PARDISO (K = P^T L L^T P in mtype 2) only the forward substitution is run: Y = L^-1 P B
    (phase 331) and B^T K^-1 B = Y^T Y, about half of a full solve's substitution time for many
    right-hand sides (measured on the tied chains' 37k-DOF leaf classes, 64-105 columns: 0.70 s
    forward against 1.29 s forward and back over four systems, one MKL thread; docs/scale.md,
    session 25). K^-1 B itself is never formed, so ``solve_spd``'s residual check is made on one
    probe column b = B 1: x = K^-1 b is solved in full on the same factors, its residual checked
    as ``solve_spd`` checks every column, and b^T x must equal 1^T (Y^T Y) 1 to round-off (a
    singular K that PARDISO factorised anyway fails one or the other). Without PARDISO:
    B^T ``solve_spd(K, B)``. ``upper_triangle`` as ``solve_spd``."""
    B = np.asarray(B, float)
    if B.ndim != 2 or B.shape[0] != K.shape[0]:
        raise ValueError(f"B must be (n, k) with n = {K.shape[0]}, got {B.shape}")
    if not pardiso_available():
        M = B.T @ solve_spd(K, B, method="splu", upper_triangle=upper_triangle)
        return 0.5 * (M + M.T)
    upper = _upper(sp.csr_matrix(K, dtype=float), upper_triangle)
    with _pardiso_errors(K.shape[0]):
        solver = _pardiso_solver()
        solver.set_phase(12)  # analysis and numerical factorization
        solver._call_pardiso(upper, np.zeros((K.shape[0], 1), order="F"))
        return _forward_gram(solver, upper, B)



class SpdFactors:
    """PARDISO's factors K = P^T L L^T P of one symmetric positive-definite K (mtype 2), kept on a
    handle of their own until ``free``, for several products with one factorisation
    (``flexcal.fem.condense_taylor``: a class's K_ii^-1 against its condensation's columns and
    their derivatives). ``half(B)``: Y = L^-1 P B, so B^T K^-1 B = Y^T Y (forward substitution
    only, as ``inverse_quadratic_form``); ``solve(B)``: K^-1 B; ``back(Y)``: K^-1 B from Y = half(B)
    (the backward substitution alone). The calling thread's MKL count
    (``solver_threads``) at each call."""

    def __init__(self, upper: sp.csr_matrix):
        self.upper = _upper(sp.csr_matrix(upper, dtype=float), True)
        self.n = self.upper.shape[0]
        _pardiso_solver()  # this thread's MKL count set, MKL loaded
        self._handle = _new_pardiso_solver()
        self._threads()
        with self._errors():
            self._handle.set_phase(12)  # analysis and numerical factorization
            self._handle._call_pardiso(self.upper, np.zeros((self.n, 1), order="F"))

    def _threads(self) -> None:
        self._handle.libmkl.MKL_Set_Num_Threads_Local(getattr(_PER_THREAD, "mkl_threads", 0))

    @contextlib.contextmanager
    def _errors(self) -> Iterator[None]:
        import pypardiso

        try:
            yield
        except pypardiso.pardiso_wrapper.PyPardisoError as error:
            self.free()
            raise _pardiso_failure(error, self.n) from error

    def _phase(self, phase: int, B: np.ndarray) -> np.ndarray:
        self._threads()
        with self._errors():
            self._handle.set_phase(phase)
            return self._handle._call_pardiso(self.upper, np.asfortranarray(B, dtype=float))

    def half(self, B: np.ndarray) -> np.ndarray:
        return self._phase(331, B)

    def solve(self, B: np.ndarray) -> np.ndarray:
        return self._phase(33, B)

    def back(self, Y: np.ndarray) -> np.ndarray:
        """K^-1 B from Y = ``half(B)``: the backward substitution alone (phase 333)."""
        return self._phase(333, Y)

    def free(self) -> None:
        if self._handle is not None:
            self._handle.free_memory(everything=True)
            self._handle = None


def spd_factors(upper: sp.csr_matrix) -> SpdFactors:
    """``SpdFactors`` of K given by its upper triangle (CSR); needs PARDISO."""
    if not pardiso_available():
        raise RuntimeError("kept factorisations need PARDISO (pypardiso and MKL); install them with setup.sh")
    return SpdFactors(upper)
