"""The improved (multi-subgroup) PSO and its plain baseline: known optima, the paper's
mechanics checked on the state, exact evaluation counts, reproducibility."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from flexcal.calibration import testfunctions as tf
from flexcal.calibration.plots import plot_convergence
from flexcal.calibration.pso import MultiSubgroupPSO, PSOSettings, identify, plain_settings
from flexcal.calibration.pso_local import (
    inside_box,
    partition_isolated,
    project_out_of_boxes,
    qmc_points,
    reflect_into,
    select_isolated,
    velocity_limits,
)

from helpers import Counting


def test_defaults_are_the_papers():
    s = PSOSettings()
    assert (s.n_particles, s.max_iterations) == (300, 150)
    assert (s.inertia_start, s.inertia_end, s.c1, s.c2) == (0.8, 0.4, 2.0, 2.0)
    assert (s.vmax_min, s.vmax_max) == (0.03, 0.07)
    assert (s.isolation_radius, s.max_isolated, s.max_subgroup_size) == (0.1, 20, 6)
    assert s.multi_subgroup and not plain_settings().multi_subgroup


def test_settings_reject_nonsense():
    with pytest.raises(ValueError, match="min_isolated"):
        PSOSettings(min_isolated=7)
    with pytest.raises(ValueError, match="global swarm remains"):
        PSOSettings(n_particles=30)
    plain_settings(n_particles=30)  # no subgroups: any swarm size will do


def test_qmc_initialization_is_warning_free_and_a_sobol_prefix():
    rng = np.random.default_rng(3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        x = qmc_points(300, 7, rng)
    assert x.shape == (300, 7) and np.all((0 <= x) & (x < 1))
    # a prefix of a Sobol sequence is far more even than random: every 1-D marginal puts
    # 300/10 points per tenth up to a few (random sampling: +-5 typical, up to ~12)
    counts = np.stack([np.histogram(x[:, j], bins=10, range=(0, 1))[0] for j in range(7)])
    assert np.all(np.abs(counts - 30) <= 3)


def test_velocity_limits_follow_sensitivity():
    np.testing.assert_allclose(velocity_limits(3, v_min=0.03, v_max=0.07, v_default=0.05), 0.05)
    v = velocity_limits(3, v_min=0.03, v_max=0.07, v_default=0.05, sensitivity=np.array([0.5, 0.0, 0.25]))
    np.testing.assert_allclose(v, [0.03, 0.07, 0.05])


def test_reflection_does_not_park_particles_on_walls():
    x = np.array([[-0.02, 0.5, 1.03]])
    v = np.array([[-0.05, 0.01, 0.04]])
    xr, vr = reflect_into(x, v, 0.0, 1.0)
    np.testing.assert_allclose(xr, [[0.02, 0.5, 0.97]])
    np.testing.assert_allclose(vr, [[0.05, 0.01, -0.04]])
    xd, vd = reflect_into(x, v, 0.0, 1.0, damping=0.5)
    np.testing.assert_allclose(vd, [[0.025, 0.01, -0.02]])


def test_isolation_partition_and_projection_helpers():
    rng = np.random.default_rng(0)
    centre = np.full(4, 0.5)
    x = centre + rng.normal(0, 0.04, (60, 4))
    f = rng.random(60)
    chosen = select_isolated(x, np.ones(60, bool), centre, radius=0.1, max_isolated=20)
    assert chosen.size == 20
    assert np.all(np.linalg.norm(x[chosen] - centre, axis=1) <= 0.1)  # the radius given to select_isolated
    others = np.setdiff1d(np.arange(60), chosen)
    assert np.linalg.norm(x[chosen] - centre, axis=1).max() <= np.linalg.norm(x[others] - centre, axis=1).min()
    groups = partition_isolated(x, f, chosen, 6)
    assert sorted(len(g) for g in groups) == [5, 5, 5, 5]
    assert sorted(np.concatenate(groups).tolist()) == sorted(chosen.tolist())
    assert groups[0][0] == chosen[np.argmin(f[chosen])]
    xp, vp, n = project_out_of_boxes(x, np.ones_like(x) * 0.01, centre[None], np.array([0.05]))
    assert n > 0 and not np.any(inside_box(xp, centre, 0.05))


@pytest.mark.parametrize("settings", [PSOSettings(), plain_settings()], ids=["improved", "plain"])
def test_one_batched_call_per_iteration_and_exact_counts(settings):
    problem = tf.rastrigin(6)
    f = Counting(problem.fitness)
    result = identify(f, 6, settings, rng=1)
    assert f.calls == result.n_iterations == 150
    assert f.rows == result.n_evaluations == 300 * 150
    assert result.history_best_f.shape == (150,)
    assert np.all(np.diff(result.history_best_f) <= 0)
    assert result.f_best == pytest.approx(problem.fitness(result.x_best[None])[0])


def test_runs_are_reproducible_from_rng():
    problem = tf.ackley(5)
    a = identify(problem.fitness, 5, PSOSettings(max_iterations=40), rng=7)
    b = identify(problem.fitness, 5, PSOSettings(max_iterations=40), rng=np.random.default_rng(7))
    c = identify(problem.fitness, 5, PSOSettings(max_iterations=40), rng=8)
    np.testing.assert_array_equal(a.x_best, b.x_best)
    np.testing.assert_array_equal(a.history_best_f, b.history_best_f)
    assert not np.array_equal(a.x_best, c.x_best)


@pytest.mark.parametrize("settings", [PSOSettings(), plain_settings()], ids=["improved", "plain"])
@pytest.mark.parametrize("problem, f_tol, x_tol", [
    # sphere: over 10 seeds the worst f was 2e-5 (x error 3e-4) improved, 2e-9 plain;
    # 1e-3 / 3e-3 leave margin for both (the improved PSO trades local precision for
    # restarts: docs/calibration.md)
    (tf.sphere(10), 1e-3, 3e-3),
    # Ackley's funnel: worst 4e-4 in f (x error 2e-6) over 10 seeds
    (tf.ackley(5), 1e-2, 1e-3),
    # Rastrigin in 2-D: 100 local minima, the global one was found in 10/10 seeds
    (tf.rastrigin(2), 1e-6, 1e-4),
], ids=lambda p: getattr(p, "name", ""))
def test_finds_known_optima(problem, f_tol, x_tol, settings):
    for seed in (0, 1, 2):
        result = identify(problem.fitness, problem.n_dims, settings, rng=seed)
        assert result.f_best - problem.f_opt <= f_tol, f"seed {seed}"
        assert np.abs(result.x_best - problem.x_opt).max() <= x_tol, f"seed {seed}"


def test_rosenbrock_valley_to_stated_accuracy():
    # A PSO with the paper's speed limits (5 % of the range per step) creeps along a curved
    # valley: over 10 seeds the 5-D shifted Rosenbrock ended at f <= 0.14 (median 0.004),
    # i.e. the swarm is in the valley but not at its end. The stated accuracy is f <= 0.5;
    # the least-squares polish finishes the job (tests/test_polish.py).
    problem = tf.rosenbrock(5)
    finals = [identify(problem.fitness, 5, PSOSettings(), rng=seed).f_best for seed in range(3)]
    assert max(finals) <= 0.5  # the stated accuracy (comment above; worst of 10 seeds 0.14)
    assert np.median(finals) <= 0.1  # median of 10 seeds was 0.004 (comment above)


def test_improved_beats_plain_on_a_deceptive_multimodal_problem():
    # Schwefel 2.26 in 10-D: the second-best minima lie far from the global one, and a
    # plain swarm settles in one of them. The improved PSO isolates the stagnated region
    # and restarts its global swarm. Over 11 seeds its median was 1070 vs the plain 1460,
    # better in all 11. Here 9 seeds, a 15 % margin on the median, and strict wins in most.
    problem = tf.schwefel(10)
    improved, plain = [], []
    for seed in range(9):
        improved.append(identify(problem.fitness, 10, PSOSettings(), rng=seed).f_best)
        plain.append(identify(problem.fitness, 10, plain_settings(), rng=seed).f_best)
    # the 15 % margin of the comment above (measured 1070 vs 1460 over 11 seeds)
    assert np.median(improved) < 0.85 * np.median(plain)
    assert sum(i < p for i, p in zip(improved, plain)) >= 6


def test_subgroup_mechanics_on_the_state():
    # A 3-D sphere with an eager stagnation test: the swarm contracts quickly, so the
    # isolation finds more than 20 particles inside the radius.
    settings = PSOSettings(stagnation_window=5, stagnation_rtol=0.5, max_iterations=60)
    problem = tf.sphere(3)
    opt = MultiSubgroupPSO(3, settings, rng=0)
    n_rounds = 0
    while not opt.stop():
        X = opt.ask()
        n_groups_before = len(opt.subgroups)
        opt.tell(problem.fitness(X))
        new = opt.subgroups[n_groups_before:]
        if new:
            n_rounds += 1
            members = [np.flatnonzero(opt.group == g.index) for g in new]
            isolated = np.concatenate(members)
            assert isolated.size <= settings.max_isolated
            assert all(1 <= m.size <= settings.max_subgroup_size for m in members)
            # isolated from inside the hypersphere around the global best of that moment
            # (the global best's position is kept through the reset; only its fitness is forgotten)
            assert np.all(np.linalg.norm(X[isolated] - opt.gbest_x, axis=1) <= settings.isolation_radius + 1e-12)
            np.testing.assert_array_equal(new[0].best_x, opt.gbest_x)
            # the rest of the swarm was reset: no personal memory left
            assert np.all(np.isinf(opt.pbest_f[opt.group == -1]))
        if opt.stop():  # the last tell only updates the bests (boxes follow them); no move
            break
        for g in opt.live_subgroups:
            # confinement: every member inside its (moving, shrinking) box
            lower, upper = opt._box(g)
            xm = opt.x[opt.group == g.index]
            assert np.all((xm >= lower - 1e-12) & (xm <= upper + 1e-12))  # round-off of the box bounds centre +- half
            # decoupling: no global particle inside a local domain
            assert not np.any(inside_box(opt.x[opt.group == -1], g.centre, g.half))
        assert np.all((opt.x >= 0) & (opt.x <= 1))
        assert len(opt.live_subgroups) <= settings.max_subgroups
    result = opt.result()
    assert n_rounds >= 2 and len(result.stagnation_iterations) == n_rounds
    assert result.n_evaluations == 60 * 300
    assert any(g.dissolved_at is not None for g in result.subgroups) or len(result.subgroups) <= 6
    assert result.f_best <= min(g.best_f for g in result.subgroups)


def test_recruits_fill_a_sparse_neighbourhood():
    # 10-D Rastrigin stagnates with few particles near the best: the first subgroup is
    # topped up to min_isolated with particles moved into its box.
    settings = PSOSettings(stagnation_window=3, stagnation_rtol=0.9, max_iterations=6)
    opt = MultiSubgroupPSO(10, settings, rng=1)
    problem = tf.rastrigin(10)
    while not opt.stop() and not opt.subgroups:
        opt.tell(problem.fitness(opt.ask()))
    assert opt.subgroups
    first = opt.subgroups[0]
    assert np.sum(opt.group == first.index) >= settings.min_isolated


def test_sensitivity_weights_set_per_dimension_speed():
    opt = MultiSubgroupPSO(3, PSOSettings(), rng=0, sensitivity=np.array([1.0, 0.0, 0.5]))
    np.testing.assert_allclose(opt.vmax, [0.03, 0.07, 0.05])


def test_failed_evaluations_count_as_worst_and_bad_tell_is_refused():
    problem = tf.sphere(4)

    def flaky(x):
        f = problem.fitness(x)
        f[::7] = np.nan
        return f

    # one tell by hand: NaN, -inf and +inf are failures and rank below every finite value
    opt = MultiSubgroupPSO(4, PSOSettings(), rng=0)
    X = opt.ask()
    f = np.arange(300, dtype=float) + 1.0
    f[:3] = [np.nan, -np.inf, np.inf]
    opt.tell(f)
    assert np.all(np.isposinf(opt.f_last[:3])) and np.all(np.isposinf(opt.pbest_f[:3]))
    assert opt.best_f == 4.0  # the best finite value, particle 3 (not the -inf failure)
    np.testing.assert_array_equal(opt.best_x, X[3])

    # a whole run where every 7th evaluation fails: the best is a real, successful evaluation ...
    result = identify(flaky, 4, PSOSettings(max_iterations=30), rng=0)
    assert result.f_best == problem.fitness(result.x_best[None])[0]
    assert result.n_evaluations == 30 * 300  # failed evaluations are counted too
    # ... and the swarm still finds the optimum: seeds 0-5 reached 2e-6 .. 3e-4 with failures
    # (2e-6 .. 1e-4 without); the best of the 300 random starts is ~4 (median ~50), so 1e-3
    # fails a run that stopped improving
    assert result.f_best < 1e-3
    opt = MultiSubgroupPSO(4, PSOSettings(), rng=0)
    with pytest.raises(ValueError, match="300 fitness values"):
        opt.tell(np.zeros(10))


def test_plain_pso_never_isolates_and_convergence_figure(tmp_path):
    problem = tf.rastrigin(5)
    plain = identify(problem.fitness, 5, plain_settings(), rng=0)
    improved = identify(problem.fitness, 5, PSOSettings(), rng=0)
    assert plain.subgroups == () and plain.stagnation_iterations == ()
    path = plot_convergence({"improved": improved, "plain": plain}, tmp_path / "convergence.png")
    assert path.read_bytes()[:4] == b"\x89PNG"
