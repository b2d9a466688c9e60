"""The paper's improved PSO (Sec. 3.2): global-dynamic multi-subgroup cooperative search.

The search runs on the unit hypercube [0, 1]^d (the paper's eta of Eq. 9: a
parameter's position inside its error range). ``MultiSubgroupPSO`` is an ask/tell
optimizer holding the real iteration state; ``identify`` runs it on a batched fitness
``f(X (n, d)) -> (n,)`` in one call. ``PSOSettings(multi_subgroup=False)`` is the plain
global-best PSO on the same code (same initialization, inertia, c1, c2, velocity
limits; no subgroups, no reset), the baseline.

One iteration (one ``tell``):
1. personal, subgroup (local) and global-swarm bests are updated from the fitness of
   the whole swarm (global and local particles, one batched evaluation);
2. stagnation test, paper Eq. 14, on the global swarm's best:
   |f(t) - f(t - k)| <= rtol |f(t - k)| + atol. ``atol`` is the noise floor (a fit
   cannot improve below the noise) and ``rtol`` makes the test scale-free;
3. on stagnation: the global particles within ``isolation_radius`` (Euclidean, unit
   space) of the global best are isolated, nearest first and at most ``max_isolated``,
   and split into subgroups of <= ``max_subgroup_size`` (the best remaining particle
   seeds a subgroup and takes its nearest neighbours). Each subgroup searches the
   hypercube of half-width ``local_half_width`` around its seed (the first one around
   the global best, whose position and fitness it inherits as local best) with its own
   local best; particles are confined by reflection at the box walls with velocity
   damping. If fewer than ``min_isolated`` particles are near the best, the worst
   global particles are moved to random points of the first box to fill it (our
   addition: otherwise a lone particle forms a subgroup that cannot search). At most
   ``max_subgroups`` live at once: the worst (by local best) are dissolved first.
   Then every remaining global particle is reset (new quasi-Monte-Carlo position,
   velocity, personal best; the global-swarm best and its history are forgotten);
4. a subgroup's box follows its local best, and a subgroup whose local best stagnates
   (same test) is re-centred on its best and its box shrunk by ``local_shrink`` (our
   addition, down to ``local_min_half_width``: the paper's "deep exploration of the
   optimal region" without a fixed box);
5. velocities ``v = w v + c1 r1 (p - x) + c2 r2 (g - x)`` (g = global-swarm best for
   global particles, the local best for subgroup members), inertia w falling linearly
   from ``inertia_start`` to ``inertia_end``, clamped per dimension (``velocity_limits``:
   3-7 % of the range, less for more sensitive dimensions); positions are reflected at
   the unit-box walls (never parked on them) and global particles that enter a local
   domain are projected onto its nearest free face with that velocity component
   reversed (``project_out_of_boxes``).

Every fitness row is counted in ``n_evaluations`` (= n_particles per iteration).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from flexcal.calibration.pso_settings import PSOResult, PSOSettings, SubgroupRecord, plain_settings
from flexcal.calibration.pso_local import (
    partition_isolated,
    project_out_of_boxes,
    qmc_points,
    reflect_into,
    select_isolated,
    velocity_limits,
)

__all__ = ["PSOSettings", "SubgroupRecord", "PSOResult", "MultiSubgroupPSO", "identify", "plain_settings"]


@dataclass(kw_only=True)
class _Subgroup:
    index: int
    created_at: int
    centre: np.ndarray
    half: float
    best_x: np.ndarray
    best_f: float
    history: list = field(default_factory=list)
    last_change: int = 0
    dissolved_at: int | None = None


class MultiSubgroupPSO:
    """Ask/tell state of the multi-subgroup PSO on the unit hypercube (see module doc).

    ``ask()`` -> X (n_particles, n_dims): the positions to evaluate (global and local
    particles together); ``tell(f)`` with f (n_particles,) advances one iteration;
    ``stop()``; ``result()``. ``group`` (n_particles,) is -1 for global particles and
    the subgroup index otherwise. Non-finite fitness counts as +inf (a failed model run).
    """

    def __init__(self, n_dims: int, settings: PSOSettings | None = None, rng=None,
                 sensitivity: np.ndarray | None = None) -> None:
        if n_dims < 1:
            raise ValueError(f"n_dims={n_dims} must be >= 1")
        self.settings = s = settings or PSOSettings()
        self.n_dims = n_dims
        self.rng = np.random.default_rng(rng)
        self.vmax = velocity_limits(n_dims, v_min=s.vmax_min, v_max=s.vmax_max, v_default=s.vmax_default,
                                    sensitivity=sensitivity)
        n = s.n_particles
        self.x = qmc_points(n, n_dims, self.rng)
        self.v = self.rng.uniform(-1.0, 1.0, (n, n_dims)) * self.vmax
        self.pbest_x = self.x.copy()
        self.pbest_f = np.full(n, np.inf)
        self.f_last = np.full(n, np.inf)
        self.group = np.full(n, -1)
        self.subgroups: list[_Subgroup] = []
        self.gbest_x = self.x[0].copy()
        self.gbest_f = np.inf
        self.best_x = self.x[0].copy()
        self.best_f = np.inf
        self.iteration = 0
        self.n_evaluations = 0
        self.n_projections = 0
        self.history_best_f: list[float] = []
        self.history_global_f: list[float] = []
        self._global_since_reset: list[float] = []
        self.stagnation_iterations: list[int] = []
        self._global_start = 0  # iteration of the last reset (restarts the inertia schedule)

    # ------------------------------------------------------------------ interface

    def ask(self) -> np.ndarray:
        """(n_particles, n_dims) positions to evaluate [unit box]."""
        return self.x.copy()

    def stop(self) -> bool:
        s = self.settings
        return self.iteration >= s.max_iterations or (s.target_fitness is not None and self.best_f <= s.target_fitness)

    def tell(self, fitness: np.ndarray) -> None:
        """Take the fitness (n_particles,) of the positions of ``ask`` and move the swarm."""
        f = np.asarray(fitness, float).reshape(-1)
        if f.shape != (self.settings.n_particles,):
            raise ValueError(f"tell needs {self.settings.n_particles} fitness values, got {f.shape[0]}")
        if self.stop():
            raise RuntimeError("the optimizer has stopped (see stop()); start a new one to continue")
        f = np.where(np.isfinite(f), f, np.inf)
        self.n_evaluations += f.size
        self.f_last = f
        self._update_bests(f)
        self.iteration += 1
        if self.stop():
            return
        fresh = np.zeros(self.settings.n_particles, bool)
        if self.settings.multi_subgroup:
            fresh |= self._shrink_stagnant_subgroups()
            if self._stagnated(self._global_since_reset):
                fresh |= self._isolate_and_reset()
        self._move(~fresh)

    def result(self, wall_s: float = 0.0) -> PSOResult:
        records = tuple(
            SubgroupRecord(index=g.index, created_at=g.created_at, dissolved_at=g.dissolved_at,
                           centre=g.centre.copy(), half_width=g.half, best_x=g.best_x.copy(), best_f=g.best_f,
                           history=np.array(g.history))
            for g in self.subgroups)
        return PSOResult(x_best=self.best_x.copy(), f_best=float(self.best_f),
                         history_best_f=np.array(self.history_best_f),
                         history_global_f=np.array(self.history_global_f), n_evaluations=self.n_evaluations,
                         n_iterations=self.iteration, stagnation_iterations=tuple(self.stagnation_iterations),
                         subgroups=records, n_projections=self.n_projections, settings=self.settings, wall_s=wall_s,
                         global_best_x=self.gbest_x.copy(), global_best_f=float(self.gbest_f))

    @property
    def live_subgroups(self) -> list[_Subgroup]:
        return [g for g in self.subgroups if g.dissolved_at is None]

    # ------------------------------------------------------------------ steps

    def _update_bests(self, f: np.ndarray) -> None:
        better = f < self.pbest_f
        self.pbest_x[better] = self.x[better]
        self.pbest_f[better] = f[better]
        for g in self.live_subgroups:
            members = np.flatnonzero(self.group == g.index)
            j = members[np.argmin(self.pbest_f[members])]
            if self.pbest_f[j] < g.best_f:
                g.best_f, g.best_x = float(self.pbest_f[j]), self.pbest_x[j].copy()
                if self.settings.local_follow_best:
                    g.centre = g.best_x.copy()
            g.history.append(g.best_f)
        glob = np.flatnonzero(self.group == -1)
        j = glob[np.argmin(self.pbest_f[glob])]
        if self.pbest_f[j] < self.gbest_f:
            self.gbest_f, self.gbest_x = float(self.pbest_f[j]), self.pbest_x[j].copy()
        for fx, xx in [(self.gbest_f, self.gbest_x)] + [(g.best_f, g.best_x) for g in self.live_subgroups]:
            if fx < self.best_f:
                self.best_f, self.best_x = fx, xx.copy()
        self.history_best_f.append(self.best_f)
        self.history_global_f.append(self.gbest_f)
        self._global_since_reset.append(self.gbest_f)

    def _stagnated(self, history: list[float]) -> bool:
        """Eq. 14 over the window k: |f(t) - f(t - k)| <= rtol |f(t - k)| + atol."""
        s = self.settings
        k = s.stagnation_window
        if len(history) <= k or not np.isfinite(history[-1 - k]):
            return False
        return abs(history[-1] - history[-1 - k]) <= s.stagnation_rtol * abs(history[-1 - k]) + s.stagnation_atol

    def _box(self, g: _Subgroup) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of a subgroup's domain, intersected with the unit box."""
        return np.clip(g.centre - g.half, 0.0, 1.0), np.clip(g.centre + g.half, 0.0, 1.0)

    def _shrink_stagnant_subgroups(self) -> np.ndarray:
        s = self.settings
        fresh = np.zeros(s.n_particles, bool)
        for g in self.live_subgroups:
            if g.half <= s.local_min_half_width or self.iteration - g.last_change < s.stagnation_window:
                continue
            if not self._stagnated(g.history):
                continue
            g.centre, g.last_change = g.best_x.copy(), self.iteration
            g.half = max(g.half * s.local_shrink, s.local_min_half_width)
            lower, upper = self._box(g)
            members = np.flatnonzero(self.group == g.index)
            self.v[members] *= s.local_shrink
            outside = members[~np.all((self.x[members] >= lower) & (self.x[members] <= upper), axis=1)]
            self.x[outside] = self.rng.uniform(lower, upper, (outside.size, self.n_dims))
            self.pbest_x[outside], self.pbest_f[outside] = self.x[outside], np.inf
            fresh[outside] = True
            kept = np.setdiff1d(members, outside)
            stale = kept[~np.all((self.pbest_x[kept] >= lower) & (self.pbest_x[kept] <= upper), axis=1)]
            self.pbest_x[stale], self.pbest_f[stale] = self.x[stale], self.f_last[stale]
        return fresh

    def _isolate_and_reset(self) -> np.ndarray:
        s, n = self.settings, self.settings.n_particles
        fresh = np.zeros(n, bool)
        is_global = self.group == -1
        isolated = select_isolated(self.x, is_global, self.gbest_x, radius=s.isolation_radius,
                                   max_isolated=s.max_isolated)
        parts = partition_isolated(self.x, self.f_last, isolated, s.max_subgroup_size)
        if isolated.size < s.min_isolated:  # fill the first subgroup with recruits (module doc)
            spare = np.setdiff1d(np.flatnonzero(is_global), isolated)
            recruits = spare[np.argsort(-self.f_last[spare], kind="stable")][: s.min_isolated - isolated.size]
            lower = np.clip(self.gbest_x - s.local_half_width, 0, 1)
            upper = np.clip(self.gbest_x + s.local_half_width, 0, 1)
            self.x[recruits] = self.rng.uniform(lower, upper, (recruits.size, self.n_dims))
            self.f_last[recruits] = np.inf
            fresh[recruits] = True
            parts = [np.concatenate([parts[0], recruits]) if parts else recruits]
        live = sorted(self.live_subgroups, key=lambda g: -g.best_f)
        for g in live[: max(0, len(live) + len(parts) - s.max_subgroups)]:  # dissolve the worst
            g.dissolved_at = self.iteration
            self.group[self.group == g.index] = -1
        for k, members in enumerate(parts):
            seed = members[0]
            if k == 0:
                centre, best_x, best_f = self.gbest_x.copy(), self.gbest_x.copy(), self.gbest_f
            else:
                centre, best_x, best_f = self.x[seed].copy(), self.x[seed].copy(), float(self.f_last[seed])
            g = _Subgroup(index=len(self.subgroups), created_at=self.iteration, centre=centre,
                          half=s.local_half_width, best_x=best_x, best_f=best_f, last_change=self.iteration)
            self.subgroups.append(g)
            self.group[members] = g.index
            lower, upper = self._box(g)
            inside = np.all((self.x[members] >= lower) & (self.x[members] <= upper), axis=1)
            self.x[members] = np.clip(self.x[members], lower, upper)  # position correction
            self.pbest_x[members] = self.x[members]
            self.pbest_f[members] = np.where(inside, self.f_last[members], np.inf)
            fresh[members[~inside]] = True
        reset = np.flatnonzero(self.group == -1)
        self.x[reset] = qmc_points(reset.size, self.n_dims, self.rng)
        self.v[reset] = self.rng.uniform(-1.0, 1.0, (reset.size, self.n_dims)) * self.vmax
        self._push_out_of_domains(reset)
        self.pbest_x[reset], self.pbest_f[reset] = self.x[reset], np.inf
        fresh[reset] = True
        self.gbest_f, self._global_since_reset = np.inf, []
        self.stagnation_iterations.append(self.iteration)
        self._global_start = self.iteration
        return fresh

    def _push_out_of_domains(self, index: np.ndarray) -> None:
        live = self.live_subgroups
        if not live or index.size == 0:
            return
        centres = np.array([g.centre for g in live])
        halves = np.array([g.half for g in live])
        self.x[index], self.v[index], n = project_out_of_boxes(self.x[index], self.v[index], centres, halves)
        self.n_projections += n

    def _inertia(self, start: int) -> float:
        """w falling linearly from inertia_start at iteration ``start`` to inertia_end at
        the last iteration."""
        s = self.settings
        span = max(1, s.max_iterations - 1 - start)
        t = min(max(self.iteration - start, 0), span)
        return s.inertia_start - (s.inertia_start - s.inertia_end) * t / span

    def _move(self, movable: np.ndarray) -> None:
        s = self.settings
        w_local = self._inertia(0)
        w_global = self._inertia(self._global_start if s.reset_inertia else 0)
        w = np.full((s.n_particles, 1), w_global)
        attractor = np.broadcast_to(self.gbest_x, self.x.shape).copy()
        vmax = np.broadcast_to(self.vmax, self.x.shape).copy()
        for g in self.live_subgroups:
            members = self.group == g.index
            attractor[members] = g.best_x
            vmax[members] = np.minimum(self.vmax, s.local_vmax_fraction * 2.0 * g.half)
            w[members] = w_local
        r1, r2 = self.rng.random((2,) + self.x.shape)
        v = w * self.v + s.c1 * r1 * (self.pbest_x - self.x) + s.c2 * r2 * (attractor - self.x)
        v = np.clip(v, -vmax, vmax)
        x = self.x + v
        x, v = reflect_into(x, v, 0.0, 1.0)
        for g in self.live_subgroups:
            members = np.flatnonzero((self.group == g.index) & movable)
            lower, upper = self._box(g)
            x[members], v[members] = reflect_into(x[members], v[members], lower, upper, s.local_damping)
        self.x[movable], self.v[movable] = x[movable], v[movable]
        self._push_out_of_domains(np.flatnonzero((self.group == -1) & movable))


def identify(fitness: Callable[[np.ndarray], np.ndarray], n_dims: int, settings: PSOSettings | None = None,
             rng=None, *, sensitivity: np.ndarray | None = None,
             callback: Callable[[MultiSubgroupPSO], None] | None = None) -> PSOResult:
    """Minimize a batched fitness on [0, 1]^n_dims with the (improved or plain) PSO.

    fitness: ``f(X (n, n_dims)) -> (n,)``, called once per iteration with the whole
    swarm; settings: ``PSOSettings()`` (the paper's) or ``plain_settings()``; rng: seed
    or Generator (runs are reproducible from it); sensitivity: (n_dims,) e.g. total Sobol
    indices for the per-dimension velocity limits; callback(optimizer) after each tell.
    """
    start = time.perf_counter()
    opt = MultiSubgroupPSO(n_dims, settings, rng, sensitivity)
    while not opt.stop():
        X = opt.ask()
        opt.tell(fitness(X))
        if callback is not None:
            callback(opt)
    return opt.result(wall_s=time.perf_counter() - start)
