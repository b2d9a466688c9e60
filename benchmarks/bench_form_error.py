"""The model-form error budget: each model at the true values against the FEM prototype.

    .venv/bin/python benchmarks/bench_form_error.py [--scenario table1[,paper]] [--provider fem]
        [--corrections fem|fem-rigid] [--scenario-seeds 1,2,3]
        [--walks 3] [--points 60] [--strokes 0.5,0.8] [--seed 1] [--breakaway 2] [--slopes]
        [--slope-grids default,provider] [--curvatures] [--curvature-pairs central,one-sided]
        [--mixed-grids default,3,4]
        [--trajectory table1=DIR/trajectory.csv ...]

Truth: the scenario's as-built virtual prototype (FEM segment stiffness by default, noise-free
curve), driven along (1) the standard trajectory and (2) random multi-actuator walks. Models,
each step adding one thing: the paper's (Eq. 1-8 as written: closed-form chains, no second
order), + FEM-informed chain compliance (docs/model.md 7), + second-order geometric terms
(docs/model.md 8; the calibration's default), + the clearance's play state with the
prototype's breakaway force given (docs/model.md 9), + the consistent second-order model:
each chain's second-order shortening from its own elements (exact joint kinematics) plus the
correction measured on the prototype's chains at the nominal design, their lateral
compatibility defect and load form (docs/model.md 10 items 5-6: the designs' large strokes),
the chain forces' and the weight's turning lever arms, Eq. 6-7 with the nut's own tangent stiffness, all solved inside
the per-point equilibrium with Newton steps on the clearance (docs/model.md 10). The prototype's breakaway force is
``--breakaway`` (comma-separated values: one table per value; the prototype's default is
2 N); ``--trajectory NAME=FILE`` adds a trajectory file (e.g. ``flexcal design``'s
trajectory.csv) for scenario NAME. Each is evaluated at the scenario's true values
by ``flexcal.validation.runs.form_floor.model_form_floor``: RMS per angle and max [urad], and
the RMS over multi-actuator postures and near a drive's unloading. ``--provider`` is the truth's
segment stiffness, ``--corrections`` the provider the model's FEM corrections (factors, slopes,
shortening) are measured on (default: the truth's; ``fem-rigid`` with ``--provider fem`` or the
other way round shows what a mismatched pair costs, docs/model.md 7 "Session 25");
``--scenario-seeds`` draws the scenario's errors with each seed (default: its own draw).

A walk (``random_walk``): 60 points from zero; at each step every actuator moves with
probability 2/3 by a uniform step of up to 0.35 x its stroke limit in a random direction,
reflected at +-stroke x A_i (A_i the standard trajectory's amplitudes): with seed 1 each
actuator reverses 15-26 times per walk and 58-59 of the 60 postures move two or three
actuators. Walk k of stroke s uses seed [seed, k, round(100 s)]. Not a test: the figures go into docs/verification-table1.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import numpy as np

ANGLES = ("theta_x", "theta_y", "theta_z")
STEP_SHARE = 0.35  # largest step per point as a share of the stroke limit (each walk reaches 0.5-1.0 of it)
MOVE_PROBABILITY = 2 / 3  # chance that an actuator moves at a step (most postures: two or three moved)


def random_walk(amplitudes: np.ndarray, n_points: int, stroke: float, rng) -> np.ndarray:
    """(n_points, 3) [m] a walk from zero inside +-stroke x amplitudes (3,) [m] (module docstring)."""
    rng = np.random.default_rng(rng)
    limit = stroke * np.asarray(amplitudes, dtype=float)
    x = np.zeros((n_points, 3))
    for k in range(1, n_points):
        step = rng.uniform(-1.0, 1.0, 3) * STEP_SHARE * limit * (rng.random(3) < MOVE_PROBABILITY)
        nxt = x[k - 1] + step
        nxt = np.where(nxt > limit, 2 * limit - nxt, nxt)  # reflect at the stroke limits
        x[k] = np.where(nxt < -limit, -2 * limit - nxt, nxt)
    return x


def _row(label: str, model: str, floor: dict) -> str:
    block = floor["models"][0]
    rms = block["all"]["rms_urad"]
    multi = block["actuators"]["multi"]
    near = block["unloading"]["near"]

    def overall(stats):
        return "—" if not stats["n"] else f"{np.sqrt(np.mean([stats['rms_urad'][a] ** 2 for a in ANGLES])):.2f}"

    return (f"| {label} | {model} | " + " / ".join(f"{rms[a]:.2f}" for a in ANGLES) + f" | {block['all']['max_urad']:.2f}"
            f" | {overall(multi)} ({multi['n']}) | {overall(near)} ({near['n']}) |")


def main(argv=None) -> int:
    from flexcal.validation.prototype.providers import stiffness_provider

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="table1")
    parser.add_argument("--provider", default="fem", choices=("fem", "fem-rigid", "analytic"))
    parser.add_argument("--corrections", default=None, choices=("fem", "fem-rigid"),
                        help="the provider of the model's FEM corrections (default: --provider's; none for analytic)")
    parser.add_argument("--scenario-seeds", default=None,
                        help="comma-separated seeds of the scenario's drawn errors (default: the scenario's own)")
    parser.add_argument("--walks", type=int, default=3)
    parser.add_argument("--points", type=int, default=60)
    parser.add_argument("--strokes", default="0.5,0.8")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--breakaway", default="2", help="the prototype's breakaway force(s) [N], comma-separated")
    parser.add_argument("--slopes", action="store_true",
                        help="add the consistent model with FEM compliance slopes (docs/model.md 7; 20 cold FEM chain "
                             "builds the first time)")
    parser.add_argument("--slope-grids", default="default",
                        help="with --slopes: the mapped grid(s) of the slopes' FEM builds, comma-separated: 'default' "
                             "(model_correction.SLOPE_ELEMENTS_THROUGH), 'provider' (the prototype's own grid) or a "
                             "number of cells through the thinnest section; one model row each (and with "
                             "--curvatures the curvatures' and shortening slopes' rows on the same grid)")
    parser.add_argument("--curvatures", action="store_true",
                        help="with --slopes: add the consistent model whose factors follow the dimensions to second "
                             "order and whose shortening correction follows them (dimension_terms.curved_space, "
                             "docs/model.md 11 session 18; 20 cold FEM chain builds per chain design the first time)")
    parser.add_argument("--curvature-pairs", default="one-sided",
                        help="with --curvatures: the mixed entries' differences, comma-separated rows "
                             "(dimension_terms.PAIR_DIFFERENCES: central, one-sided; the default's one-sided)")
    parser.add_argument("--mixed-grids", default="default",
                        help="with --curvatures: the mapped grid(s) of the mixed curvatures' builds alone, "
                             "comma-separated: 'default' (dimension_terms.MIXED_ELEMENTS_THROUGH), 'same' (the "
                             "slopes' grid) or a number of cells through the thinnest section; one row each")
    parser.add_argument("--trajectory", action="append", default=[], metavar="SCENARIO=FILE",
                        help="a trajectory file (columns xa1_mm, xa2_mm, xa3_mm) to add for that scenario")
    args = parser.parse_args(argv)
    strokes = [float(s) for s in args.strokes.split(",")]
    forces = [float(f) for f in args.breakaway.split(",")]
    files = dict(item.split("=", 1) for item in args.trajectory)
    start = time.perf_counter()
    provider = stiffness_provider(args.provider, progress=False, workers=None)
    kind = args.corrections or (args.provider if args.provider != "analytic" else None)
    corrections = None if kind is None else (provider if kind == args.provider else
                                             stiffness_provider(kind, progress=False, workers=None))
    seeds = [None] if args.scenario_seeds is None else [int(s) for s in args.scenario_seeds.split(",")]
    for name in args.scenario.split(","):
        for seed in seeds:
            for force in forces:
                _table(name, provider, corrections, args, strokes, force, files.get(name), seed)
    print(f"bench_form_error: {time.perf_counter() - start:.0f} s", file=sys.stderr)
    return 0


def _table(scenario_name, provider, corrections, args, strokes, force, trajectory_file, seed) -> None:
    """One table: every trajectory of one scenario (its errors drawn with ``seed``, None: its own)
    at one prototype breakaway force [N]; truth on ``provider``, the model's FEM corrections on
    ``corrections`` (None: none, the analytic truth's closed-form model)."""
    from flexcal.model.parameters import parameter_space
    from flexcal.model.trajectory import standard_trajectory
    from flexcal.validation.prototype.scenario import load_scenario, read_trajectory
    from flexcal.validation.prototype.truth import make_truth
    from flexcal.validation.runs.form_floor import model_form_floor, truth_from_run
    from flexcal.validation.runs.chain_kinematics import consistent_space
    from flexcal.validation.runs.model_correction import corrected_space


    drawn = load_scenario(scenario_name) if seed is None else load_scenario(scenario_name, seed=seed)
    scenario = dataclasses.replace(drawn, breakaway_force=force)
    paper = parameter_space(scenario.space.mechanism)
    fem = corrected_space(paper, corrections) if corrections is not None else paper
    second = dataclasses.replace(fem, second_order=True)
    consistent = dataclasses.replace(consistent_space(fem, corrections or provider), breakaway_force=force)
    models = (("paper's model", paper), ("+ FEM-informed compliance", fem), ("+ second order (default)", second),
              (f"+ play state (F_b {force:g} N given)", dataclasses.replace(second, breakaway_force=force)),
              ("+ consistent: chain kinematics from its elements (S corrected at nominal, lateral defect, "
               "load form), lever arms, nut tangent, solved with the clearance", consistent))
    if args.slopes and corrections is not None:
        from flexcal.validation.runs.model_correction import SLOPE_ELEMENTS_THROUGH, compliance_slopes

        for grid in args.slope_grids.split(","):
            through = {"default": SLOPE_ELEMENTS_THROUGH, "provider": None}.get(grid)
            through = float(grid) if grid not in ("default", "provider") else through
            slopes = tuple(float(v) for v in compliance_slopes(paper, corrections, elements_through=through).ravel())
            shown = f"{through:g} through" if through is not None else "the prototype's grid"
            sloped = dataclasses.replace(consistent, compliance_slopes=slopes)
            models += ((f"+ FEM compliance factors following the dimensions (slopes at nominal, {shown})", sloped),)
            if args.curvatures:
                from flexcal.validation.runs.dimension_terms import curved_space

                from flexcal.validation.runs.dimension_terms import MIXED_ELEMENTS_THROUGH

                for pairs in args.curvature_pairs.split(","):
                    for mixed_grid in args.mixed_grids.split(","):
                        mixed = {"default": MIXED_ELEMENTS_THROUGH, "same": None}.get(mixed_grid)
                        mixed = float(mixed_grid) if mixed_grid not in ("default", "same") else mixed
                        mixed_shown = "" if mixed is None else f", the mixed ones on {mixed:g} through"
                        models += ((f"+ the factors to second order ({pairs} pairs) and the shortening correction "
                                    f"following the dimensions (curvatures, shortening slopes at nominal, {shown}"
                                    f"{mixed_shown})",
                                    curved_space(sloped, corrections, pairs=pairs, elements_through=through,
                                                 mixed_elements_through=mixed)),)
    amplitudes = standard_trajectory(scenario.space.mechanism).amplitudes
    trajectories = [("standard (77 points)", scenario.inputs, scenario.leg)]
    if trajectory_file:
        designed, leg = read_trajectory(trajectory_file)
        trajectories.append((f"{trajectory_file} ({len(designed)} points)", designed, leg))
    for stroke in strokes:
        for k in range(args.walks):
            walk_seed = [args.seed, k, round(100 * stroke)]
            inputs = random_walk(amplitudes, args.points, stroke, walk_seed)
            trajectories.append((f"walk {k + 1}, stroke {stroke:g}, seed {walk_seed}", inputs,
                                 np.ones(args.points, dtype=int)))
    print(f"\nbench_form_error: scenario {scenario_name}"
          + ("" if seed is None else f" (errors drawn with seed {seed})")
          + f", provider {args.provider}, corrections {args.corrections or 'the provider'}, prototype breakaway force "
          f"{force:g} N, amplitudes "
          + ", ".join(f"{a * 1e3:.3f}" for a in amplitudes) + " mm; urad, true values vs the noise-free prototype curve",
          flush=True)
    print("| trajectory | model | RMS θx / θy / θz | max | RMS multi-actuator (n) | RMS near unloading (n) |")
    print("|---|---|---|---:|---:|---:|")
    for label, inputs, leg in trajectories:
        case = dataclasses.replace(scenario, inputs=inputs, leg=leg)
        run = make_truth(case, provider).run
        truth = truth_from_run(run, case.values)
        for name, space in models:
            try:
                print(_row(label, name, model_form_floor(truth, inputs, space)), flush=True)
            except Exception as error:  # a model that does not converge on a walk is a result too
                print(f"| {label} | {name} | failed: {error} | | | |", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
