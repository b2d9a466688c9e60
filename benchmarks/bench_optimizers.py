"""Peer benchmark of the identification optimizers (not a test).

Same problem, same evaluation budget, same run, several seeds, medians:

- improved PSO (``flexcal.calibration.pso``, paper Sec. 3.2), with and without a
  least-squares polish of its distinct candidate solutions (overall, global-swarm and
  subgroup bests, ``PSOResult.candidates``; the lowest sum of squares wins). The polish
  gets what the swarm leaves of the budget: the swarm runs
  ``budget // n_particles - polish_iterations`` iterations, 100 of 150 by default;
- the plain global-best PSO on the same code, also with a polish of its best (a control:
  what the subgroups add);
- pyswarms ``GlobalBestPSO`` (300 particles, the standard constriction-equivalent
  w = 0.7298, c1 = c2 = 1.49618, pyswarms' default boundary handling);
- ``scipy.optimize.differential_evolution`` (vectorized, ``popsize`` 15 -> 15 d members,
  no polish);
- CMA-ES (``cma``, start at the centre, sigma0 0.3, bounds [0, 1]);
- ``scipy.optimize.least_squares`` (trf) from the nominal point, our batched Jacobian.

Every fitness or residual row counts as one evaluation. The population methods
minimize the paper's fitness (Eq. 13: mean per-point residual norm); least squares
minimizes the sum of squares of the same residuals. Reported per method: final
fitness (Eq. 13 at the returned point), parameter error (max and RMS over the
sensitive parameters, fraction of the range), evaluations, wall time.

The problem is an argument: any object with ``residuals(X (n, d)) -> (n, m)``,
``fitness(X (n, d)) -> (n,)``, ``x_true (d,)``, ``sensitive (d,) bool`` and ``name``
(``flexcal.calibration.testfunctions.LeastSquaresProblem``), so the mechanism model
plugs in unchanged. Run ``python benchmarks/bench_optimizers.py --help``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import warnings
from typing import Callable

import numpy as np

from flexcal.calibration.polish import EvaluationCounter, least_squares_polish, norm_sum_polish, polish_candidates
from flexcal.calibration.pso import PSOSettings, identify
from flexcal.calibration.testfunctions import curve_fit_problem


def _capped(function: Callable, budget: int) -> EvaluationCounter:
    return EvaluationCounter(function, max_evaluations=budget)


def run_improved(problem, budget: int, seed: int, *, polish: bool, settings: PSOSettings,
                 polish_iterations: int = 50) -> tuple[np.ndarray, int]:
    n_iter = budget // settings.n_particles - (polish_iterations if polish else 0)
    s = dataclasses.replace(settings, max_iterations=n_iter)
    counter = _capped(problem.fitness, budget)
    result = identify(counter, problem.n_dims, s, rng=seed)
    if polish:
        left = budget - counter.n_evaluations
        best, _, used = polish_candidates(problem.residuals, result.candidates(), max_evaluations=(2 * left) // 3,
                                          select=problem.fitness)
        # finish on Eq. 13 itself (IRLS) with what is left: the sum of squares' minimizer is
        # not the fitness minimizer when the model cannot fit exactly
        refined = norm_sum_polish(problem.residuals, best.x, max_evaluations=left - used)
        return refined.x, counter.n_evaluations + used + refined.n_evaluations  # refined: never above its start
    return result.x_best, counter.n_evaluations


def run_plain(problem, budget: int, seed: int, *, settings: PSOSettings, polish: bool = False,
              polish_iterations: int = 50) -> tuple[np.ndarray, int]:
    n_iter = budget // settings.n_particles - (polish_iterations if polish else 0)
    s = dataclasses.replace(settings, multi_subgroup=False, max_iterations=n_iter)
    counter = _capped(problem.fitness, budget)
    result = identify(counter, problem.n_dims, s, rng=seed)
    if polish:
        polished = least_squares_polish(problem.residuals, result.x_best,
                                        max_evaluations=budget - counter.n_evaluations)
        return polished.x, counter.n_evaluations + polished.n_evaluations
    return result.x_best, counter.n_evaluations


def run_pyswarms(problem, budget: int, seed: int, n_particles: int = 300) -> tuple[np.ndarray, int]:
    import logging

    from pyswarms.single import GlobalBestPSO

    logging.getLogger("pyswarms").setLevel(logging.ERROR)
    np.random.seed(seed)  # pyswarms draws from numpy's global state; it takes no Generator
    d = problem.n_dims
    counter = _capped(problem.fitness, budget)
    opt = GlobalBestPSO(n_particles=n_particles, dimensions=d, options={"c1": 1.49618, "c2": 1.49618, "w": 0.7298},
                        bounds=(np.zeros(d), np.ones(d)))
    _, pos = opt.optimize(counter, iters=budget // n_particles, verbose=False)
    return np.asarray(pos, float), counter.n_evaluations


def run_de(problem, budget: int, seed: int, popsize: int = 15) -> tuple[np.ndarray, int]:
    from scipy.optimize import differential_evolution

    d = problem.n_dims
    counter = _capped(problem.fitness, budget)
    members = popsize * d
    res = differential_evolution(lambda x: counter(np.atleast_2d(x.T)), [(0.0, 1.0)] * d, vectorized=True,
                                 updating="deferred", popsize=popsize, maxiter=budget // members - 1, tol=0.0,
                                 polish=False, init="sobol" if members & (members - 1) == 0 else "latinhypercube",
                                 rng=seed)
    return res.x, counter.n_evaluations


def run_cma(problem, budget: int, seed: int) -> tuple[np.ndarray, int]:
    import cma

    d = problem.n_dims
    counter = _capped(problem.fitness, budget)
    es = cma.CMAEvolutionStrategy(np.full(d, 0.5), 0.3, {"bounds": [0.0, 1.0], "seed": seed + 1, "verbose": -9,
                                                         "maxfevals": budget, "tolfun": 0.0, "tolx": 1e-14})
    best_x, best_f = np.full(d, 0.5), np.inf
    while not es.stop() and counter.n_evaluations + es.popsize <= budget:
        X = np.array(es.ask())
        f = counter(X)
        es.tell(list(X), list(f))
        if f.min() < best_f:
            best_f, best_x = float(f.min()), X[np.argmin(f)].copy()
    return best_x, counter.n_evaluations


def run_least_squares(problem, budget: int, seed: int) -> tuple[np.ndarray, int]:
    x0 = getattr(problem, "x_nominal", None)
    x0 = np.full(problem.n_dims, 0.5) if x0 is None else np.asarray(x0, float)
    res = least_squares_polish(problem.residuals, x0, max_evaluations=budget)
    return res.x, res.n_evaluations


@dataclasses.dataclass(frozen=True)
class Options:
    """What the methods share: our PSO's settings and the swarm iterations traded for
    the polish in "improved PSO + polish" (100 + polish of 150 by default)."""

    settings: PSOSettings = dataclasses.field(default_factory=PSOSettings)
    polish_iterations: int = 50


METHODS = {
    "improved PSO + polish": lambda p, b, s, o: run_improved(p, b, s, polish=True, settings=o.settings,
                                                             polish_iterations=o.polish_iterations),
    "improved PSO": lambda p, b, s, o: run_improved(p, b, s, polish=False, settings=o.settings),
    "plain PSO": lambda p, b, s, o: run_plain(p, b, s, settings=o.settings),
    "plain PSO + polish": lambda p, b, s, o: run_plain(p, b, s, settings=o.settings, polish=True,
                                                       polish_iterations=o.polish_iterations),
    "pyswarms GlobalBestPSO": lambda p, b, s, o: run_pyswarms(p, b, s, o.settings.n_particles),
    "scipy differential_evolution": lambda p, b, s, o: run_de(p, b, s),
    "CMA-ES (cma)": lambda p, b, s, o: run_cma(p, b, s),
    "least_squares trf (nominal start)": lambda p, b, s, o: run_least_squares(p, b, s),
}


def benchmark(problem, *, budget: int = 45_000, seeds=range(5), methods=None, options: Options | None = None,
              log=print) -> list[dict]:
    """One row per (method, seed): fitness, parameter errors, evaluations, wall time."""
    options = options or Options()
    rows = []
    for name in methods or METHODS:
        for seed in seeds:
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                x, n_eval = METHODS[name](problem, budget, int(seed), options)
            wall = time.perf_counter() - start
            err = np.abs(np.asarray(x) - problem.x_true)[problem.sensitive]
            row = {"method": name, "seed": int(seed), "fitness": float(problem.fitness(np.asarray(x)[None])[0]),
                   "max_param_error": float(err.max()), "rms_param_error": float(np.sqrt(np.mean(err**2))),
                   "n_evaluations": int(n_eval), "wall_s": wall}
            rows.append(row)
            log(f"  {name:36s} seed {seed}: fitness {row['fitness']:.4g}, max error {row['max_param_error']:.3g}, "
                f"{n_eval} evaluations, {wall:.1f} s")
    return rows


def median_table(rows: list[dict]) -> str:
    """Markdown table of the medians per method (in the order the methods ran)."""
    names = list(dict.fromkeys(r["method"] for r in rows))
    lines = ["| method | median fitness | median max param. error | median RMS param. error | evaluations | "
             "wall s | seeds |", "|---|---|---|---|---|---|---|"]
    for name in names:
        sel = [r for r in rows if r["method"] == name]
        med = {k: float(np.median([r[k] for r in sel])) for k in
               ("fitness", "max_param_error", "rms_param_error", "n_evaluations", "wall_s")}
        lines.append(f"| {name} | {med['fitness']:.4g} | {med['max_param_error']:.3g} | {med['rms_param_error']:.3g} "
                     f"| {med['n_evaluations']:.0f} | {med['wall_s']:.1f} | {len(sel)} |")
    return "\n".join(lines) + "\n"


def mechanism_problem():
    """The mount itself: the nine Table 1 drive sources from the table-1 curve of the virtual
    prototype (analytic segment stiffness: no FEM needed; truth still has exact kinematics
    and the breakaway band), the structural sources held at their true values. Sensitive =
    the sources the trajectory can see (D1/D2 are compressed throughout: their CL and mu
    leave no trace, see docs/verification-table1.md)."""
    from types import SimpleNamespace

    from flexcal.calibration.problem import CalibrationProblem
    from flexcal.model.parameters import parameter_space
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.segments import analytic_provider
    from flexcal.validation.prototype.truth import make_truth
    from flexcal.model.parameters import DRIVE_SOURCE_NAMES

    scenario = load_scenario("table1")
    measurement = make_truth(scenario, analytic_provider()).measurement
    space = parameter_space()
    sub = space.subset(DRIVE_SOURCE_NAMES, fixed=dict(zip(space.all_names, scenario.values)))
    problem = CalibrationProblem(space=sub, inputs=measurement.inputs, angles=measurement.angles)
    truth = np.array([scenario.values[space.index(n)] for n in sub.names])
    blind = {"D1.CL", "D1.mu", "D2.CL", "D2.mu"}
    return SimpleNamespace(name="mechanism-table1 (9 drive sources, prototype truth)", n_dims=sub.n_params,
                           residuals=problem.residuals, fitness=problem.fitness, x_true=sub.to_unit(truth),
                           sensitive=np.array([n not in blind for n in sub.names]),
                           x_nominal=np.clip(sub.to_unit(sub.nominal_vector), 0.0, 1.0))


PROBLEMS = {
    "mechanism-table1": mechanism_problem,
    "curve20-ripple": lambda: curve_fit_problem(20, n_insensitive=3, screw_ripple=0.05),
    "curve20": lambda: curve_fit_problem(20, n_insensitive=3),
    "curve45": lambda: curve_fit_problem(45, n_insensitive=3),
    "curve20-ripple-noise": lambda: curve_fit_problem(20, n_insensitive=3, screw_ripple=0.05, noise=1.0),
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problem", choices=sorted(PROBLEMS), default="curve20-ripple")
    parser.add_argument("--budget", type=int, default=45_000, help="evaluations per run (default 300 x 150)")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--methods", nargs="*", choices=sorted(METHODS), default=None)
    parser.add_argument("--json", help="write every row to this JSON file")
    parser.add_argument("--polish-iterations", type=int, default=50,
                        help="swarm iterations given up to the polish in 'improved PSO + polish' (default 50 of 150)")
    args = parser.parse_args(argv)
    problem = PROBLEMS[args.problem]()
    print(f"# {problem.name}: d = {problem.n_dims}, budget {args.budget}, seeds 0..{args.seeds - 1}", flush=True)
    rows = benchmark(problem, budget=args.budget, seeds=range(args.seeds), methods=args.methods,
                     options=Options(polish_iterations=args.polish_iterations), log=lambda s: print(s, flush=True))
    print()
    print(median_table(rows))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"problem": problem.name, "budget": args.budget, "rows": rows}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
