"""Settings and results of the PSO (``flexcal.calibration.pso``): frozen data only.

``PSOSettings`` holds every setting of the improved multi-subgroup PSO (defaults are the
paper's Sec. 3.2 values where it gives one, ours otherwise, said per field);
``plain_settings()`` the plain global-best baseline; ``PSOResult`` and
``SubgroupRecord`` what a run returns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PSOSettings", "plain_settings", "SubgroupRecord", "PSOResult"]


@dataclass(frozen=True, kw_only=True)
class PSOSettings:
    """Every setting of the improved PSO. Distances and speeds are in the unit search
    space (fractions of each parameter's range); [P] = the paper's value, [ours] = a
    choice where the paper is silent.

    n_particles, max_iterations: 300, 150 [P] (every iteration evaluates all particles).
    inertia_start, inertia_end: w from 0.8 to 0.4, linear in the iteration [P].
    c1, c2: cognitive and social coefficients, 2.0 [P].
    vmax_min, vmax_max: per-dimension speed limit 3-7 % of the range, lower for more
      sensitive dimensions when sensitivity weights are given [P]; vmax_default: 5 %
      without weights [ours: the middle of the paper's band].
    multi_subgroup: False gives the plain global-best PSO (the baseline).
    stagnation_window k [iterations], stagnation_rtol, stagnation_atol [fitness units]:
      Eq. 14 with eps = rtol |f(t - k)| + atol [ours: k = 10, rtol = 1 %; set atol to
      ~1 % of the expected noise floor of the fitness for noisy data, where relative
      progress stops meaning anything]. Over the test suite (tests/test_pso.py, docs)
      rtol = 1e-3 fired too late to help, 3e-2 too early (a slowly descending swarm was
      broken up).
    isolation_radius: 0.1, hypersphere around the global best [P]; max_isolated: 20 per
      round [P]; max_subgroup_size: 6 [P].
    min_isolated: 6 [ours]: fewer particles near the best are topped up with recruits
      moved into the first box.
    max_subgroups: 6 live subgroups at once [ours, from the six swarms of Fig. 11]; the
      worst are dissolved (their particles rejoin the global swarm) to make room.
    local_half_width: 0.1, half-width of a subgroup's hypercube [ours: = the radius];
    local_vmax_fraction: speed limit of members, a fraction of the box width [ours];
    local_damping: velocity factor after a reflection at a box wall [ours];
    local_shrink, local_min_half_width: a stagnating subgroup re-centres on its best
      and shrinks its box by this factor, down to this half-width [ours];
    local_follow_best: the box centre follows the subgroup's best [ours].
    reset_inertia: also restart the inertia schedule of a reset global swarm [ours;
      off: it did not help on the test problems].
    target_fitness: stop early once the best fitness reaches it (None: run all iterations).
    """

    n_particles: int = 300
    max_iterations: int = 150
    inertia_start: float = 0.8
    inertia_end: float = 0.4
    c1: float = 2.0
    c2: float = 2.0
    vmax_min: float = 0.03
    vmax_max: float = 0.07
    vmax_default: float = 0.05
    multi_subgroup: bool = True
    stagnation_window: int = 5
    stagnation_rtol: float = 1e-2
    stagnation_atol: float = 0.0
    isolation_radius: float = 0.1
    max_isolated: int = 20
    max_subgroup_size: int = 6
    min_isolated: int = 6
    max_subgroups: int = 6
    local_half_width: float = 0.1
    local_vmax_fraction: float = 0.2
    local_damping: float = 0.5
    local_shrink: float = 0.5
    local_min_half_width: float = 1e-3
    local_follow_best: bool = True
    reset_inertia: bool = False
    target_fitness: float | None = None

    def __post_init__(self) -> None:
        def need(ok: bool, text: str) -> None:
            if not ok:
                raise ValueError(text)

        need(self.n_particles >= 2, f"n_particles={self.n_particles} must be >= 2")
        need(self.max_iterations >= 1, f"max_iterations={self.max_iterations} must be >= 1")
        need(0 <= self.inertia_end and 0 <= self.inertia_start < 1.5, "inertia weights must be in [0, 1.5)")
        need(self.c1 >= 0 and self.c2 >= 0, "c1 and c2 must be >= 0")
        need(0 < self.vmax_min <= self.vmax_max <= 1 and 0 < self.vmax_default <= 1,
             f"need 0 < vmax_min={self.vmax_min} <= vmax_max={self.vmax_max} <= 1 and 0 < vmax_default <= 1")
        need(self.stagnation_window >= 1, f"stagnation_window={self.stagnation_window} must be >= 1")
        need(self.stagnation_rtol >= 0 and self.stagnation_atol >= 0, "stagnation tolerances must be >= 0")
        need(self.isolation_radius > 0, f"isolation_radius={self.isolation_radius} must be > 0")
        need(self.max_subgroup_size >= 1, f"max_subgroup_size={self.max_subgroup_size} must be >= 1")
        need(1 <= self.min_isolated <= self.max_subgroup_size,
             f"min_isolated={self.min_isolated} must be in [1, max_subgroup_size={self.max_subgroup_size}]")
        need(self.max_isolated >= self.min_isolated,
             f"max_isolated={self.max_isolated} must be >= min_isolated={self.min_isolated}")
        need(self.max_subgroups * self.max_subgroup_size >= self.max_isolated,
             f"max_subgroups x max_subgroup_size = {self.max_subgroups * self.max_subgroup_size} must hold "
             f"max_isolated={self.max_isolated} particles")
        if self.multi_subgroup:
            need(self.n_particles > self.max_subgroups * self.max_subgroup_size,
                 f"n_particles={self.n_particles} must exceed max_subgroups x max_subgroup_size = "
                 f"{self.max_subgroups * self.max_subgroup_size} so that a global swarm remains")
        need(0 < self.local_half_width <= 0.5, f"local_half_width={self.local_half_width} must be in (0, 0.5]")
        need(0 < self.local_min_half_width <= self.local_half_width,
             f"local_min_half_width={self.local_min_half_width} must be in (0, local_half_width]")
        need(0 < self.local_shrink <= 1, f"local_shrink={self.local_shrink} must be in (0, 1]")
        need(0 <= self.local_damping <= 1, f"local_damping={self.local_damping} must be in [0, 1]")
        need(0 < self.local_vmax_fraction <= 1, f"local_vmax_fraction={self.local_vmax_fraction} must be in (0, 1]")


def plain_settings(**overrides) -> PSOSettings:
    """Settings of the plain global-best PSO baseline (no subgroups, no reset)."""
    return PSOSettings(multi_subgroup=False, **overrides)


@dataclass(frozen=True, kw_only=True)
class SubgroupRecord:
    """A local subgroup's life: index, created_at / dissolved_at [iteration] (None = alive
    at the end), centre (d,) and half_width of its final box [unit], best_x (d,), best_f,
    history (n_lived,) of its local best fitness after each iteration it lived."""

    index: int
    created_at: int
    dissolved_at: int | None
    centre: np.ndarray
    half_width: float
    best_x: np.ndarray
    best_f: float
    history: np.ndarray


@dataclass(frozen=True, kw_only=True)
class PSOResult:
    """Outcome of ``identify``.

    x_best (d,) [unit box], f_best; history_best_f (n_iterations,): best fitness found
    after each iteration (Fig. 7d); history_global_f (n_iterations,): the global swarm's
    own best (restarts after every reset); n_evaluations: fitness rows evaluated;
    stagnation_iterations: iterations at which subgroups were isolated and the global
    swarm reset; subgroups: one record per subgroup (Fig. 11); n_projections: global
    particles pushed out of local domains; wall_s [s]; global_best_x (d,), global_best_f:
    the global swarm's own best at the end (since its last reset; inf if it was reset
    by the last iteration).
    """

    x_best: np.ndarray
    f_best: float
    history_best_f: np.ndarray
    history_global_f: np.ndarray
    n_evaluations: int
    n_iterations: int
    stagnation_iterations: tuple[int, ...]
    subgroups: tuple[SubgroupRecord, ...]
    n_projections: int
    settings: PSOSettings
    wall_s: float = 0.0
    global_best_x: np.ndarray | None = None
    global_best_f: float = float("inf")

    def candidates(self, min_distance: float = 0.05) -> np.ndarray:
        """(k, d) distinct good points, best first: the overall best, the global swarm's
        best and every subgroup's best (alive or dissolved) - the paper's "sets of
        relatively optimal solutions" (Fig. 11). A point within ``min_distance``
        (Euclidean, unit space) of a better one already taken is skipped. Polishing each
        (``flexcal.calibration.polish.polish_candidates``) guards against a swarm whose
        overall best sits in a refined but wrong basin."""
        points = [(self.f_best, self.x_best)]
        if self.global_best_x is not None and np.isfinite(self.global_best_f):
            points.append((self.global_best_f, self.global_best_x))
        points += [(g.best_f, g.best_x) for g in self.subgroups if np.isfinite(g.best_f)]
        points.sort(key=lambda item: item[0])
        chosen: list[np.ndarray] = []
        for _, x in points:
            if all(np.linalg.norm(x - c) >= min_distance for c in chosen):
                chosen.append(np.asarray(x, float))
        return np.array(chosen)
