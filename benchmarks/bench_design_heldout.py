"""A designed trajectory against the standard one: identification and held-out prediction (issue #28).

    .venv/bin/python benchmarks/bench_design_heldout.py --out runs/heldout/std-s1 --seed 1 \
        [--trajectory runs/design/trajectory.csv] [--scenario table1] [--model second-order|consistent] \
        [--noise-urad 0.5] [--walk-seed 28] [--walk-points 77] [--dimension-terms quadratic] [--start REPORT]

Runs what ``flexcal verify --scenario S --seed N --noise-urad 0.5 [--trajectory T] [--model M]``
runs (the same parser and defaults, FEM prototype; report.json written to --out; with
--dimension-terms and --start as verify's), then the
held-out test: the calibration model at the identified values against the noise-free prototype
of the same seed along a random multi-actuator walk (``bench_form_error.random_walk``:
--walk-points postures inside the standard trajectory's strokes, seed --walk-seed), never
measured by the identification. Also the model at the true values on that walk (the model's
own floor there: what no estimate can beat). Prints one JSON line and writes it to
OUT/heldout.json: the errors of the drive sources identified alone (their base parameters are
pure), the fit RMS, the held-out RMS and the floor.
Not a test (minutes per run on the FEM prototype); the figures go into docs/calibration.md 10.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_form_error import random_walk  # noqa: E402

DRIVES = ("D1.x0", "D2.x0", "D3.x0", "D1.CL", "D2.CL", "D3.CL", "D1.mu", "D2.mu", "D3.mu")


def _table1_error(name: str, row: dict) -> float:
    """The error of a drive row as Table 1 gives it: x0 in um, CL in mm, mu relative in %."""
    if name.endswith(".x0"):
        return row["abs_error"] * 1e3  # display mm -> um
    if name.endswith(".CL"):
        return row["abs_error"]
    return 100 * row["rel_error"]


def drive_rows(report: dict) -> dict:
    """Every drive row of Table 1 from a verify report.json, alone (a pure base parameter) or not:
    identified and true value (display units), the error as Table 1 gives it, the z-score."""
    pure = set(report.get("base_parameters", {}).get("pure", []))
    rows = {r["name"]: r for r in report["parameters"]}
    return {n: {"alone": n in pure, "identified": rows[n]["identified"], "preset": rows[n]["preset"],
                "error": _table1_error(n, rows[n]), "z": rows[n]["z_score"]} for n in DRIVES}


def form_floor(report: dict) -> dict:
    """The report's model-form floor, overall: RMS per angle and max [urad] per model."""
    floor = report.get("model_form_floor", {})
    if not floor.get("available"):
        return {"available": False}
    return {m["model"]: {"name": m["name"], "rms_urad": m["all"]["rms_urad"], "max_urad": m["all"]["max_urad"]}
            for m in floor["models"]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True)
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--trajectory", default=None)
    parser.add_argument("--scenario", default="table1")
    parser.add_argument("--model", default="second-order")
    parser.add_argument("--noise-urad", type=float, default=0.5)
    parser.add_argument("--walk-seed", type=int, default=28)
    parser.add_argument("--walk-points", type=int, default=77)
    parser.add_argument("--provider", default="fem", help="the prototype's segment stiffness (fem, analytic)")
    parser.add_argument("--dimension-terms", default="linear", choices=("linear", "quadratic"),
                        help="flexcal verify --dimension-terms (--model consistent)")
    parser.add_argument("--start", default=None, metavar="REPORT", help="flexcal verify --start REPORT")
    args = parser.parse_args(argv)

    from flexcal.calibration.problem import CalibrationProblem
    from flexcal.model.trajectory import standard_trajectory
    from flexcal.validation.cli import main as main_cli
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import make_truth

    verify_argv = ["verify", "--scenario", args.scenario, "--seed", str(args.seed), "--noise-urad",
                   str(args.noise_urad), "--model", args.model, "--provider", args.provider, "--out", args.out, "--quiet", "--force"]
    if args.trajectory:
        verify_argv += ["--trajectory", args.trajectory]
    if args.dimension_terms != "linear":
        verify_argv += ["--dimension-terms", args.dimension_terms]
    if args.start:
        verify_argv += ["--start", args.start]
    captured = {}

    # flexcal verify's own run, with its space and values kept for the held-out walk
    from flexcal.validation.runs import verify as runs_verify

    run_verify = runs_verify.run_verify

    def keep(measurement, space, *a, **k):
        result = run_verify(measurement, space, *a, **k)
        captured.update(space=space, result=result, measurement=measurement)
        return result

    runs_verify.run_verify = keep
    started = time.perf_counter()
    try:
        status = main_cli(verify_argv)
    finally:
        runs_verify.run_verify = run_verify
    verify_wall = time.perf_counter() - started
    if status != 0 or "result" not in captured:
        raise SystemExit(f"flexcal verify failed (status {status})")
    space, result, measurement = captured["space"], captured["result"], captured["measurement"]
    report = result.report

    scenario = load_scenario(args.scenario, seed=args.seed, noise_urad=args.noise_urad)
    amplitudes = standard_trajectory(scenario.space.mechanism).amplitudes
    walk_inputs = random_walk(amplitudes, args.walk_points, 1.0, args.walk_seed)
    walk = dataclasses.replace(scenario, inputs=walk_inputs, leg=np.ones(args.walk_points, int), noise=np.zeros(3))
    walk_angles = make_truth(walk, stiffness_provider(args.provider, progress=False), progress=False).measurement.angles
    problem = CalibrationProblem(space=space, inputs=walk_inputs, angles=walk_angles)
    unit = space.to_unit(result.values[space.active_indices])
    true_unit = space.to_unit(scenario.values[space.active_indices])
    residual, floor = problem.residuals(np.vstack([unit, true_unit]))

    pure = set(report.get("base_parameters", {}).get("pure", []))
    rows = {r["name"]: r for r in report["parameters"]}
    alone = [n for n in DRIVES if n in pure]
    out = {"scenario": args.scenario, "provider": args.provider, "seed": args.seed, "trajectory": args.trajectory or "standard",
           "model": args.model, "dimension_terms": args.dimension_terms, "start": args.start,
           "verify_argv": verify_argv, "n_points": int(measurement.n_points), "fit_rms_urad": report["fit_rms_urad"],
           "fit_over_noise": report.get("fit_rms_over_noise_floor"),
           "alone": alone, "pure": sorted(pure),
           "abs_error": {n: rows[n]["abs_error"] for n in alone},  # display units (x0 mm, CL mm, mu -)
           "z": {n: rows[n]["z_score"] for n in alone},
           # every drive row of Table 1, alone or not: x0 error in um, CL in mm, mu relative in %
           "drives": drive_rows(report),
           "form_floor": form_floor(report),
           "verify_wall_s": verify_wall,
           "heldout_rms_urad": float(np.sqrt(np.mean(residual ** 2)) * 1e6),
           "heldout_floor_urad": float(np.sqrt(np.mean(floor ** 2)) * 1e6),
           "walk": {"points": args.walk_points, "stroke": "standard", "seed": args.walk_seed}}
    Path(args.out, "heldout.json").write_text(json.dumps(out, indent=1))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
