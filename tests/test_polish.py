"""Least-squares polish: recovery of preset parameters, exact evaluation counts, budget."""

from __future__ import annotations

import numpy as np
import pytest

from flexcal.calibration import testfunctions as tf
from flexcal.calibration.polish import batched_jacobian_fd, least_squares_polish
from flexcal.calibration.pso import PSOSettings, identify

from helpers import Counting


def quadratic_residuals(x):
    """r(X (n, 3)) -> (n, 4) with an analytic Jacobian (below)."""
    x = np.atleast_2d(x)
    return np.column_stack([x[:, 0] ** 2, x[:, 0] * x[:, 1], np.sin(x[:, 2]), x[:, 1] + 3 * x[:, 2]])


def quadratic_jacobian(x):
    return np.array([[2 * x[0], 0, 0], [x[1], x[0], 0], [0, 0, np.cos(x[2])], [0, 1, 3]])


@pytest.mark.parametrize("scheme, step, tol", [
    # forward error ~ step * curvature / 2 + eps / step ~ 1e-8: tolerance 1e-6
    ("forward", 1.5e-8, 1e-6),
    # central error ~ step^2 (1e-10) + eps / step (1e-11): tolerance 1e-9
    ("central", 1e-5, 1e-9),
])
def test_batched_jacobian_matches_analytic_and_loop(scheme, step, tol):
    x = np.array([0.3, 0.6, 0.9])
    f = Counting(quadratic_residuals)
    J, r0 = batched_jacobian_fd(f, x, step=step, scheme=scheme)
    assert f.calls == 1  # one batched call of all perturbed points
    np.testing.assert_allclose(J, quadratic_jacobian(x), atol=tol)  # tol: the parametrized bounds above
    # the unperturbed point of the same batch: round-off only
    np.testing.assert_allclose(r0, quadratic_residuals(x[None])[0], atol=1e-15)
    if scheme == "forward":  # batched == looped, to rounding
        looped = np.column_stack([(quadratic_residuals((x + step * e)[None])[0] - r0) / step for e in np.eye(3)])
        # the same points, the same arithmetic: round-off only
        np.testing.assert_allclose(J, looped, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("scheme", ["forward", "central"])
def test_jacobian_stays_inside_the_bounds(scheme):
    # at x = 1 and x = 0 the differences turn one-sided: error ~ step * curvature (2 here)
    x = np.array([1.0, 0.0, 0.5])
    seen = []
    J, _ = batched_jacobian_fd(lambda X: (seen.append(X.copy()), quadratic_residuals(X))[1], x, step=1e-5,
                               scheme=scheme)
    points = np.concatenate(seen)
    assert np.all((points >= 0) & (points <= 1))
    # one-sided at the bounds: step x curvature (2) / 2 = 1e-5 (comment above); 3x
    np.testing.assert_allclose(J, quadratic_jacobian(x), atol=3e-5)


@pytest.mark.parametrize("batched", [True, False], ids=["batched-jacobian", "scipy-2-point"])
def test_polish_recovers_preset_parameters_and_counts_every_evaluation(batched):
    problem = tf.curve_fit_problem(20, n_insensitive=3)
    start = np.clip(problem.x_true + np.random.default_rng(0).uniform(-0.1, 0.1, 20), 0, 1)
    f = Counting(problem.residuals)
    result = least_squares_polish(f, start, batched_jacobian=batched)
    assert result.n_evaluations == f.rows  # nothing uncounted
    # trf's nfev leaves the Jacobian points out; we count them: d per Jacobian at least
    assert result.n_evaluations >= result.nfev + 20 * result.njev if batched else result.n_evaluations > result.nfev
    # noise-free data: the fit is exact to rounding; 1e-8 of the range is far below any
    # physical tolerance and far above what a converged trf leaves (~1e-14 measured)
    np.testing.assert_allclose(result.x, problem.x_true, atol=1e-8)
    assert result.rms < 1e-12  # noise-free: measured 4e-14 (was 1e-9)
    assert result.cost < result.cost0


def test_polish_respects_an_evaluation_budget():
    problem = tf.curve_fit_problem(20, n_insensitive=3)
    f = Counting(problem.residuals)
    result = least_squares_polish(f, np.full(20, 0.5), max_evaluations=100)
    assert f.rows <= 100 and result.n_evaluations == f.rows
    assert result.status == -10 and result.cost <= result.cost0


def test_pso_then_polish_recovers_a_multimodal_fit_with_noise():
    # 12 parameters, a screw ripple that makes the fit multimodal, noise of 1 unit: the
    # swarm finds the basin, the polish the least-squares point. With noise the target is
    # statistical: errors within 5 standard deviations (identifiability's parameter_std)
    from flexcal.calibration.identifiability import identifiability

    problem = tf.curve_fit_problem(12, n_insensitive=0, screw_ripple=0.02, noise=1.0, rng=3)
    swarm = identify(problem.fitness, 12, PSOSettings(n_particles=150, max_iterations=60), rng=0)
    polished = least_squares_polish(problem.residuals, swarm.x_best)
    report = identifiability(problem.residuals, polished.x, problem.names, noise=1.0)
    error = np.abs(polished.x - problem.x_true)
    assert np.all(error <= 5 * report.parameter_std), error / report.parameter_std
    # the residual is at the noise floor: rms of 231 unit-normal residuals minus 12 fitted
    # degrees of freedom is ~0.97 +- 0.05
    assert 0.8 < polished.rms < 1.1


@pytest.mark.slow
def test_improved_pso_with_candidate_polish_finds_the_basin_more_often_than_plain():
    # The screw ripple makes the 20-D fit multimodal: a swarm often settles in a wrong
    # basin (x0_3 / CL_3 shifted by about one screw lead). Measured over seeds 0-15 with
    # 100 iterations + polish: improved (k = 5) with all candidates polished 10/16 in the
    # right basin (8/16 with k = 10), plain PSO + polish of its best 6/16.
    from flexcal.calibration.polish import polish_candidates
    from flexcal.calibration.pso import plain_settings

    problem = tf.curve_fit_problem(20, n_insensitive=3, screw_ripple=0.05)
    wins = {"improved": 0, "plain": 0}
    for seed in range(16):
        improved = identify(problem.fitness, 20, PSOSettings(max_iterations=100), rng=seed)
        best, _, _ = polish_candidates(problem.residuals, improved.candidates(), max_evaluations=15_000)
        wins["improved"] += np.abs(best.x - problem.x_true)[problem.sensitive].max() < 0.05
        plain = identify(problem.fitness, 20, plain_settings(max_iterations=100), rng=seed)
        polished = least_squares_polish(problem.residuals, plain.x_best, max_evaluations=15_000)
        wins["plain"] += np.abs(polished.x - problem.x_true)[problem.sensitive].max() < 0.05
    assert wins["improved"] >= 9 and wins["improved"] >= wins["plain"] + 2, wins


def test_calibration_problem_batched_equals_looped():
    problem = tf.curve_fit_problem(15, n_insensitive=2, screw_ripple=0.02, noise=0.5)
    X = np.random.default_rng(5).random((7, 15))
    batched_r, batched_f = problem.residuals(X), problem.fitness(X)
    looped_r = np.vstack([problem.residuals(x[None]) for x in X])
    looped_f = np.concatenate([problem.fitness(x[None]) for x in X])
    np.testing.assert_allclose(batched_r, looped_r, rtol=1e-13, atol=1e-12)  # same arithmetic, batched: round-off only
    np.testing.assert_allclose(batched_f, looped_f, rtol=1e-13)  # as above
    assert batched_r.shape == (7, 77 * 3)
    # Eq. 13 shape: mean over points of the per-point (3-angle) residual norm
    np.testing.assert_allclose(batched_f, np.linalg.norm(batched_r.reshape(7, 77, 3), axis=2).mean(axis=1))


def test_norm_sum_polish_finds_the_geometric_median():
    # Eq. 13 is a sum of per-point norms: for residuals r_i = x - a_i its minimizer is the
    # geometric median of the a_i, not their mean (the sum-of-squares minimizer). Points
    # skewed so the two differ by ~0.1 of the box.
    from scipy.optimize import minimize

    from flexcal.calibration.polish import norm_sum_polish

    rng = np.random.default_rng(3)
    a = np.vstack([rng.uniform(0.1, 0.3, size=(12, 2)), rng.uniform(0.6, 0.9, size=(4, 2))])

    def residuals(X):
        return (np.atleast_2d(X)[:, None, :] - a[None]).reshape(np.atleast_2d(X).shape[0], -1)

    def eq13(x):
        return np.linalg.norm(x[None] - a, axis=1).sum()

    squares = least_squares_polish(residuals, np.full(2, 0.5))
    # linear least squares, trf xtol 1e-12: measured 2e-15 (was 1e-8)
    np.testing.assert_allclose(squares.x, a.mean(axis=0), atol=1e-12)
    result = norm_sum_polish(residuals, squares.x, point_size=2, rounds=200)
    reference = minimize(eq13, a.mean(axis=0), method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-14})
    assert result.cost <= eq13(squares.x) - 1e-3  # it moved off the mean, downhill
    assert result.cost == pytest.approx(eq13(result.x), rel=1e-12)  # cost is Eq. 13's sum
    # Weiszfeld converges linearly; 200 rounds reach the median to ~1e-6 of the box
    np.testing.assert_allclose(result.x, reference.x, atol=1e-5)
    assert result.n_evaluations > squares.n_evaluations // 10  # every round counted


def test_norm_sum_polish_respects_the_budget():
    from flexcal.calibration.polish import norm_sum_polish

    a = np.array([[0.2, 0.2], [0.8, 0.3], [0.4, 0.9]])
    calls = []

    def residuals(X):
        calls.append(np.atleast_2d(X).shape[0])
        return (np.atleast_2d(X)[:, None, :] - a[None]).reshape(np.atleast_2d(X).shape[0], -1)

    result = norm_sum_polish(residuals, np.array([0.5, 0.5]), point_size=2, max_evaluations=40)
    assert sum(calls) <= 40 and result.n_evaluations == sum(calls)


def test_polish_candidates_can_select_by_another_objective():
    # two basins of r(x) = (x - 0.2)(x - 0.8) + offset: the sum of squares prefers the
    # basin at 0.8 (tilted), a different objective (distance to 0.2) the one at 0.2
    from flexcal.calibration.polish import polish_candidates

    def residuals(X):
        x = np.atleast_2d(X)[:, 0]
        return np.stack([(x - 0.2) * (x - 0.8), 0.05 * (x - 0.8)], axis=1)

    default, _, used_default = polish_candidates(residuals, np.array([[0.15], [0.85]]))
    assert default.x[0] == pytest.approx(0.8, abs=1e-12)  # both residuals vanish at 0.8: measured 3e-15 (was 1e-6)
    chosen, results, used = polish_candidates(residuals, np.array([[0.15], [0.85]]),
                                              select=lambda X: np.abs(X[:, 0] - 0.2))
    assert len(results) == 2 and chosen.x[0] < 0.5  # the basins are at 0.2 and 0.8: 0.5 separates them
    assert used == used_default + 2  # the two selection evaluations are counted
