"""Sparse SPD solves with several right-hand sides."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from flexcal.fem.solve import pardiso_available, solve_spd


def _laplacian_3d(n: int) -> sp.csr_matrix:
    """7-point Laplacian on an n^3 grid plus a small shift: SPD, cond ~ 4 n^2."""
    one = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    eye = sp.identity(n)
    L = sp.kron(sp.kron(one, eye), eye) + sp.kron(sp.kron(eye, one), eye) + sp.kron(sp.kron(eye, eye), one)
    return (L + 1e-3 * sp.identity(n**3)).tocsr()


def test_pardiso_gives_the_same_bits_twice():
    """PARDISO's threaded factorization summed in a changing order: at this size (216k
    unknowns, 2 threads) every one of 4 solves in a process gave other last bits. With
    MKL's reproducibility mode (fem/solve.py) the same system solves to the same bits.
    ~5 s a solve here."""
    if not pardiso_available():
        pytest.skip("pypardiso / MKL not available")
    import os

    assert os.environ["MKL_CBWR"]  # set before MKL started (unless the user chose a mode)
    K = _laplacian_3d(60)
    rhs = np.random.default_rng(0).standard_normal((K.shape[0], 6))
    first = solve_spd(K, rhs, method="pardiso")
    assert np.array_equal(first, solve_spd(K, rhs, method="pardiso"))


def test_solves_in_two_threads_at_once_match_one_at_a_time():
    """Each thread has its own PARDISO handle (no lock since session 9: the FEM segment
    builds run in threads of one process) and, inside ``solver_threads(1)``, one MKL
    thread of its own while other threads keep MKL's count. Two threads solving at once
    give the bits of the same solves one after the other on one MKL thread."""
    if not pardiso_available():
        pytest.skip("pypardiso / MKL not available")
    import threading

    from flexcal.fem import solve
    from flexcal.fem.solve import solver_threads

    K = _laplacian_3d(30)  # 27k unknowns: ~0.3 s a solve, long enough to overlap
    rhs = [np.random.default_rng(seed).standard_normal((K.shape[0], 6)) for seed in (1, 2)]
    with solver_threads(1):
        alone = [solve_spd(K, b, method="pardiso") for b in rhs]
        assert solve._pardiso_solver().libmkl.MKL_Get_Max_Threads() == 1
    outside = solve._pardiso_solver().libmkl.MKL_Get_Max_Threads()
    results, counts = [None, None], [None, None]

    def work(i: int) -> None:
        with solver_threads(1):
            results[i] = solve_spd(K, rhs[i], method="pardiso")
            counts[i] = solve._pardiso_solver().libmkl.MKL_Get_Max_Threads()

    threads = [threading.Thread(target=work, args=(i,)) for i in (0, 1)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert counts == [1, 1] and solve._pardiso_solver().libmkl.MKL_Get_Max_Threads() == outside
    assert all(np.array_equal(r, a) for r, a in zip(results, alone))
    with pytest.raises(ValueError, match="must be an integer >= 1"):
        with solver_threads(0):
            pass


def test_a_solve_on_one_solver_thread_opens_no_second_openmp_thread():
    """PARDISO's factorization opens OpenMP teams of OpenMP's own count, whatever
    ``MKL_Set_Num_Threads_Local`` says: inside ``solver_threads(1)`` a second thread worked
    beside it and spun for KMP_BLOCKTIME after every region (the factorization of a chain's
    segment class took 1.7x its wall in CPU). ``solver_threads`` holds the calling thread's
    OpenMP count too, and gives it back after. Run on a fresh thread, as the FEM build jobs
    are, with that thread's OpenMP count set to 2 first (so the check means the same on a
    one-core machine)."""
    if not pardiso_available():
        pytest.skip("pypardiso / MKL not available")
    import threading
    import time

    from threadpoolctl import threadpool_info, threadpool_limits

    from flexcal.fem.solve import solver_threads

    def openmp_counts() -> set[int]:
        return {info["num_threads"] for info in threadpool_info() if info["user_api"] == "openmp"}

    K = _laplacian_3d(40)  # 64k unknowns: ~1 s of factorization on one core
    rhs = np.random.default_rng(3).standard_normal((K.shape[0], 2))
    found = {}

    def work() -> None:
        with threadpool_limits(2, user_api="openmp"):
            solve_spd(K[:8, :8], rhs[:8], method="pardiso")  # loads MKL and its OpenMP runtime
            with solver_threads(1):
                found["inside"] = openmp_counts()
                time.sleep(0.3)  # > KMP_BLOCKTIME (200 ms): the teams of earlier tests' solves stop spinning
                wall, cpu = time.perf_counter(), time.process_time()
                solve_spd(K, rhs, method="pardiso")
                found["cpu_over_wall"] = (time.process_time() - cpu) / (time.perf_counter() - wall)
            found["after"] = openmp_counts()

    thread = threading.Thread(target=work)
    thread.start()
    thread.join()
    if not found["after"]:
        pytest.skip("MKL runs without an OpenMP runtime here")
    assert found["inside"] == {1} and found["after"] == {2}
    # one thread works: CPU <= wall, plus 15 % for the rest of this process (pytest, the
    # interpreter's own threads); the second thread's spin made it 1.6-1.7 alone (measured)
    assert found["cpu_over_wall"] < 1.15


@pytest.mark.parametrize("method", ["auto", "pardiso", "splu", "spsolve", "amg"])
def test_methods_solve_several_right_hand_sides(method):
    if method == "pardiso" and not pardiso_available():
        pytest.skip("pypardiso / MKL not available")
    K = _laplacian_3d(8)
    rng = np.random.default_rng(0)
    X_true = rng.standard_normal((K.shape[0], 6))
    rhs = K @ X_true
    near_null = np.ones((K.shape[0], 1))  # the Laplacian's near-null space: constants
    X = solve_spd(K, rhs, method=method, near_null_space=near_null)
    assert X.shape == rhs.shape
    # direct: eps x cond (~3e2) ~ 1e-13; AMG-CG: relative residual 1e-10 x cond ~ 3e-8
    tolerance = 1e-6 if method == "amg" else 1e-10
    np.testing.assert_allclose(X, X_true, atol=tolerance * np.abs(X_true).max())  # bounds from the comment above
    x = solve_spd(K, rhs[:, 0], method=method, near_null_space=near_null)
    assert x.shape == (K.shape[0],)
    np.testing.assert_allclose(x, X[:, 0], atol=tolerance * np.abs(X_true).max())  # as above


def test_errors_say_what_to_do():
    K = _laplacian_3d(3)
    with pytest.raises(ValueError, match="unknown solver method"):
        solve_spd(K, np.ones(27), method="cholmod")
    with pytest.raises(ValueError, match="near_null_space"):
        solve_spd(K, np.ones(27), method="amg")
    with pytest.raises(ValueError, match="rows"):
        solve_spd(K, np.ones(5))
    singular = sp.csr_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    for method in ("splu", "pardiso") if pardiso_available() else ("splu",):
        with pytest.raises(ValueError, match="singular|not positive definite|not held"):
            solve_spd(singular, np.array([1.0, 0.0]), method=method)


def test_free_body_is_reported_as_singular():
    """A body held nowhere: PARDISO meets a zero pivot, SuperLU returns garbage that the
    residual check catches."""
    from flexcal.fem.assembly import assemble_stiffness
    from flexcal.fem.structured import box_tet_mesh
    from flexcal.geometry.params import Material

    K = assemble_stiffness(box_tet_mesh(0.04, 0.01, 0.01, 4, 1, 1), Material())
    load = np.zeros(K.shape[0])
    load[5] = 1.0
    for method in ("splu", "pardiso") if pardiso_available() else ("splu",):
        with pytest.raises(ValueError, match="not held"):
            solve_spd(K, load, method=method)


def test_pardiso_out_of_memory_is_named(monkeypatch):
    """MKL PARDISO's error -2 is 'not enough memory', not an unconstrained body: the message
    must say so (the diagnosis benchmark once failed with the wrong advice)."""
    if not pardiso_available():
        pytest.skip("pypardiso / MKL not available")
    import pypardiso

    import flexcal.fem.solve as solve

    class OutOfMemory:
        def factorize(self, matrix):
            raise pypardiso.pardiso_wrapper.PyPardisoError(-2)

        def solve(self, matrix, rhs):  # solve_spd factorizes and solves in one call (phase 13)
            raise pypardiso.pardiso_wrapper.PyPardisoError(-2)

        def free_memory(self, everything=False):
            pass

    monkeypatch.setattr(solve, "_pardiso_solver", lambda: OutOfMemory())
    with pytest.raises(RuntimeError, match="not enough memory"):
        solve_spd(_laplacian_3d(3), np.ones(27), method="pardiso")


def test_inverse_quadratic_form_from_the_forward_substitution_alone():
    """B^T K^-1 B from PARDISO's forward substitution (Y^T Y) against B^T X of a full solve,
    on the whole matrix and on its upper triangle, and without PARDISO (splu)."""
    from flexcal.fem.solve import inverse_quadratic_form

    K = _laplacian_3d(14)
    B = np.zeros((K.shape[0], 9))
    B[:300] = np.random.default_rng(1).standard_normal((300, 9))  # sparse rows, as a face's fields
    expected = B.T @ solve_spd(K, B, method="splu")
    for M in (inverse_quadratic_form(K, B), inverse_quadratic_form(sp.triu(K, format="csr"), B, upper_triangle=True)):
        assert np.array_equal(M, M.T)
        # two direct solves of a matrix with cond ~ 800: they agree to ~1e-15 of the largest entry
        assert np.max(np.abs(M - expected)) < 1e-12 * np.max(np.abs(expected))


def test_inverse_quadratic_form_refuses_a_free_body():
    """A body held nowhere (its rigid motions free) is refused, not condensed into garbage:
    PARDISO's zero pivot or the probe column's check."""
    from flexcal.fem.assembly import assemble_stiffness
    from flexcal.fem.solve import inverse_quadratic_form
    from flexcal.fem.structured import box_tet_mesh
    from flexcal.geometry.params import Material

    K = assemble_stiffness(box_tet_mesh(0.04, 0.01, 0.01, 4, 1, 1), Material())
    B = np.zeros((K.shape[0], 2))
    B[5, 0] = B[7, 1] = 1.0
    with pytest.raises(ValueError, match="not held"):
        inverse_quadratic_form(K, B)


@pytest.mark.skipif(not pardiso_available(), reason="kept factors are PARDISO's")
def test_kept_factors_give_the_full_solve_from_its_halves():
    """``SpdFactors``: back(half(B)) is solve(B) to the bit (the forward then the backward
    substitution are what phase 33 runs), half(B)^T half(B) is B^T K^-1 B, and a freed handle
    holds nothing."""
    from flexcal.fem.solve import one_thread, spd_factors

    K = sp.triu(_laplacian_3d(12), format="csr")
    B = np.random.default_rng(2).standard_normal((K.shape[0], 7))
    with one_thread():
        factors = spd_factors(K)
        Y, X = factors.half(B), factors.solve(B)
        assert np.array_equal(factors.back(Y), X)
        # two products of one factorisation, cond ~ 600: 1e-12 of the largest entry
        assert np.max(np.abs(Y.T @ Y - B.T @ X)) < 1e-12 * np.max(np.abs(B.T @ X))
        factors.free()
        factors.free()  # twice is harmless
