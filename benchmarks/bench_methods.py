"""MAP vs free least squares vs the paper's method (Sobol + improved PSO) on the same curves.

    .venv/bin/python benchmarks/bench_methods.py runs/truth-a/curves.csv [runs/truth-b/curves.csv ...]
        [--methods map,free,paper] [--model-stiffness fem] [--particles 300 --iterations 150]

For each file and method: the held-out RMS (each whole leg left out in turn, the method fitted
on the others, the left-out leg predicted; pooled RMS over all folds), then the method on all
points: Table 1 figures over the sources it identifies alone / calls identifiable, fit RMS
and wall time. Prints one table with the ratios of every method's held-out RMS to MAP's,
measured in the same run. Not a test: the figures go into docs/verification-table1.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import numpy as np


def _subset(measurement, points):
    from flexcal.validation.measurements import Measurement

    return Measurement(point=measurement.point[points], time=measurement.time[points], leg=measurement.leg[points],
                       inputs=measurement.inputs[points], angles=measurement.angles[points], extras={},
                       metadata=measurement.metadata)


def run_method(measurement, space, method: str, settings, presets):
    from flexcal.calibration.estimation import held_out_folds
    from flexcal.model.forward import forward
    from flexcal.validation.runs.verify import run_verify

    verify_settings = dataclasses.replace(settings, method=method)
    squares, count = 0.0, 0
    for fold in held_out_folds(measurement.leg):
        train = np.setdiff1d(np.arange(measurement.n_points), fold)
        fit = run_verify(_subset(measurement, train), space, verify_settings, progress=False)
        predicted = forward(fit.values, measurement.inputs[fold], space=space).angles[0]
        r = predicted - measurement.angles[fold]
        squares += float(np.sum(r ** 2))
        count += r.size
    start = time.perf_counter()
    full = run_verify(measurement, space, verify_settings, presets=presets, progress=False)
    wall = time.perf_counter() - start
    figures = {row["figure"]: row for row in full.report.get("paper_comparison", [])}
    identifiable = [r for r in full.report["parameters"] if r["identifiable"] and "preset" in r]
    error = np.sqrt(np.mean([r["error_of_range"] ** 2 for r in identifiable])) if identifiable else float("nan")
    return {"held_out_rms_urad": np.sqrt(squares / count) * 1e6, "fit_rms_urad": full.report["fit_rms_urad"],
            "parameter_error_pct_of_range": 100 * error, "n_identifiable": len(identifiable),
            "x0_um": figures.get("initial_position_max_abs_error_um", {}).get("ours_identifiable"),
            "wall_s": wall}


def main(argv=None) -> int:
    from flexcal.calibration.pso_settings import PSOSettings
    from flexcal.model.parameters import parameter_space
    from flexcal.validation.measurements import read_measurement
    from flexcal.validation.runs.model_correction import model_space
    from flexcal.validation.prototype.scenario import mechanism_from_metadata
    from flexcal.validation.runs.verify import VerifySettings

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+")
    parser.add_argument("--methods", default="map,free,paper")
    parser.add_argument("--model-stiffness", default="fem", choices=("fem", "closed-form"))
    parser.add_argument("--particles", type=int, default=300)
    parser.add_argument("--iterations", type=int, default=150)
    args = parser.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",")]
    settings = VerifySettings(pso=dataclasses.replace(PSOSettings(), n_particles=args.particles,
                                                      max_iterations=args.iterations))
    print("| file | method | held-out RMS [urad] | / MAP | fit RMS [urad] | param. error [% of range], "
          "identifiable | n identifiable | x0 max error [um] | wall [s] |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for path in args.files:
        measurement = read_measurement(path)
        found = measurement.metadata.get("preset_errors")
        presets = parameter_space().build_values({e["name"]: e["value"] for e in found}, display_units=True) \
            if found else None
        space = model_space(args.model_stiffness, True, mechanism=mechanism_from_metadata(measurement.metadata))
        rows = {m: run_method(measurement, space, m, settings, presets) for m in methods}
        reference = rows.get("map", next(iter(rows.values())))["held_out_rms_urad"]
        for method, row in rows.items():
            x0 = "—" if row["x0_um"] is None else f"{row['x0_um']:.3g}"
            print(f"| {path} | {method} | {row['held_out_rms_urad']:.3g} | {row['held_out_rms_urad'] / reference:.2f} | "
                  f"{row['fit_rms_urad']:.3g} | {row['parameter_error_pct_of_range']:.3g} | {row['n_identifiable']} | "
                  f"{x0} | {row['wall_s']:.1f} |")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
