"""``flexcal identify``: identification alone (paper Sec. 3.2, Eq. 13).

Identifies the chosen error sources from a measurement CSV (or a scenario's synthetic
curves) with the improved multi-subgroup PSO and the least-squares polish, the other
sources staying at nominal; no Sobol screening (``flexcal sensitivity`` gives the
ranking, ``flexcal verify`` runs both). Writes DIR/report.json (identified values, the
errors against the presets when the data are synthetic, fit, identifiability),
DIR/report.md, DIR/fit.png and DIR/convergence.png.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from .options import add_out
from .options import add_source_options, load_source

__all__ = ["configure", "run", "parse_sources", "EXAMPLES", "DEFAULT_CONFIG"]

EXAMPLES = (
    "flexcal identify --scenario table1 --out runs/ident                  # the nine Table 1 drive sources",
    "flexcal identify --data curves.csv --sources D1.x0,D1.CL,D1.mu --remove-offset --out runs/d1",
    "flexcal identify --scenario table1 --provider analytic --particles 40 --iterations 20 --out runs/quick",
)
DEFAULT_CONFIG = {"model_stiffness": "fem", "second_order": True, "provider": "fem", "sources": "table1", "particles": 300, "iterations": 150, "polish": True,
                  "remove_offset": False, "calibration_seed": 0}


def configure(parser: argparse.ArgumentParser) -> None:
    from .options import add_identification_options, add_model_options

    add_source_options(parser)
    parser.add_argument("--sources", metavar="NAMES",
                        help="comma-separated error sources to identify (docs/parameters.md), 'table1' (the nine "
                             "drive sources x0, CL, mu) or 'all' (default %(default)s)")
    add_identification_options(parser)
    add_model_options(parser)
    parser.add_argument("--calibration-seed", type=int, metavar="N", help="seed of the PSO (default %(default)s)")
    add_out(parser, what="report.json, report.md, fit.png, convergence.png")


def parse_sources(text: str, names: tuple[str, ...]) -> tuple[str, ...]:
    """'table1' | 'all' | 'A,B,...' -> names in the parameter space's order."""
    from flexcal.model.parameters import DRIVE_SOURCE_NAMES

    text = text.strip()
    if text == "all":
        return tuple(names)
    wanted = DRIVE_SOURCE_NAMES if text == "table1" else tuple(s.strip() for s in text.split(",") if s.strip())
    unknown = [n for n in wanted if n not in names]
    if unknown or not wanted:
        raise ValueError(f"--sources: unknown error source(s) {unknown or [text]}; use names like D1.CL "
                         f"(docs/parameters.md), 'table1' or 'all'")
    return tuple(n for n in names if n in wanted)


def run(args: argparse.Namespace) -> int:
    from flexcal.calibration.identifiability import identifiability
    from flexcal.calibration.plots import plot_convergence
    from flexcal.calibration.polish import polish_candidates
    from flexcal.calibration.problem import CalibrationProblem
    from flexcal.calibration.pso import identify
    from flexcal.calibration.pso_settings import PSOSettings
    from flexcal.model.forward import ideal_angles
    from flexcal.model.parameters import parameter_space

    from ..progress import progress_bar
    from .common import show_progress
    from ..runs.model_correction import model_space
    from ..output import staged_output, write_json
    from ..reports.plots import plot_misalignment_curves
    from ..runs.verify import _parameter_rows, remove_return_offsets

    if args.particles < 2 or args.iterations < 1:
        raise ValueError(f"--particles={args.particles} must be >= 2 and --iterations={args.iterations} >= 1")
    selected = parse_sources(args.sources, parameter_space().names)
    settings = dataclasses.replace(PSOSettings(), n_particles=args.particles, max_iterations=args.iterations)
    progress = show_progress(args)
    measurement, presets = load_source(args, parameter_space(), progress=progress)
    from flexcal.calibration.pipeline import check_determined

    from .options import executor_options
    from ..prototype.scenario import mechanism_from_metadata

    check_determined(measurement.n_points, len(selected))
    space = model_space(args.model_stiffness, args.second_order, progress=progress,
                        mechanism=mechanism_from_metadata(measurement.metadata), **executor_options(args))
    angles = remove_return_offsets(measurement) if args.remove_offset else measurement.angles
    sub = space.subset(selected)
    problem = CalibrationProblem(space=sub, inputs=measurement.inputs, angles=angles)
    start = time.perf_counter()
    with progress_bar(args.iterations, "PSO", enabled=progress, unit="iteration") as bar:
        pso = identify(problem.fitness, sub.n_params, settings, rng=args.calibration_seed,
                       callback=lambda _: bar.update(1))
    x_best, polish = pso.x_best, None
    if args.polish:
        polish, _, _ = polish_candidates(problem.residuals, pso.candidates(), max_evaluations=pso.n_evaluations)
        if problem.fitness(polish.x[None])[0] <= pso.f_best:
            x_best = polish.x
    wall_s = time.perf_counter() - start
    fitted = problem.model_angles(x_best[None])[0][0]
    residual = fitted - angles
    per_point = np.linalg.norm(residual, axis=1)
    fit_rms = float(np.sqrt(np.mean(residual ** 2)))
    noise = args.noise_urad * 1e-6 if args.noise_urad else max(fit_rms, 1e-9)
    ident = identifiability(problem.residuals, x_best, sub.names, noise=noise)
    identified = sub.full_values(sub.from_unit(x_best))
    rows = _parameter_rows(space, identified, presets, selected, set(ident.meaningful_names))
    summary = {"n_points": measurement.n_points, "n_identified": len(selected), "fit_rms_urad": fit_rms * 1e6,
               "fit_max_urad": float(per_point.max() * 1e6), "fitness_eq13_urad": float(per_point.mean() * 1e6),
               "n_evaluations": int(problem.log.n_candidates), "rank": int(ident.rank),
               "condition_number": float(ident.condition_number), "seed": args.calibration_seed}
    report = {
        "summary": summary, "config": args.config, "selected": list(selected), "parameters": rows,
        "identifiability": {"rank": ident.rank, "n_parameters": len(ident.names),
                            "condition_number": ident.condition_number, "groups": [list(g) for g in ident.groups],
                            "meaningful": list(ident.meaningful_names)},
        "pso": {"n_evaluations": pso.n_evaluations, "history_best_f_urad": pso.history_best_f * 1e6},
        "polish": None if polish is None else {"rms_urad": polish.rms * 1e6, "used": bool(np.array_equal(x_best, polish.x))},
        "offset_removed": bool(args.remove_offset),
        "wall_s": wall_s,
    }
    has_preset = presets is not None
    lines = ["# Identification (improved PSO + polish)", "",
             f"{len(selected)} sources identified from {measurement.n_points} postures; fit RMS {fit_rms * 1e6:.4g} urad, "
             f"max ||Δθ|| {summary['fit_max_urad']:.4g} urad; identifiability rank {ident.rank} of {len(ident.names)}, "
             f"condition number {ident.condition_number:.3g}.", "",
             "![fit](fit.png)", "", "![convergence](convergence.png)", "", "## Identified sources", "",
             "| parameter | unit | identified | " + ("preset | abs error | " if has_preset else "") + "identifiable |",
             "|---|---|---:|" + ("---:|---:|" if has_preset else "") + "---|"]
    for r in (r for r in rows if r["was_identified"]):
        cells = [f"`{r['name']}`", r["unit"], f"{r['identified']:.5g}"]
        if has_preset:
            cells += [f"{r['preset']:.5g}", f"{r['abs_error']:.3g}"]
        lines.append("| " + " | ".join(cells + ["yes" if r["identifiable"] else "no"]) + " |")
    ideal = ideal_angles(measurement.inputs, space)
    with staged_output(args.out, replace=args.force) as staging:
        write_json(staging / "report.json", report)
        (staging / "report.md").write_text("\n".join(lines) + "\n")
        classes = measurement.metadata.get("prototype", {}).get("point_class") or ["S3"] * measurement.n_points
        plot_misalignment_curves(staging / "fit.png", angles - ideal, classes, leg=measurement.leg,
                                 fitted=fitted - ideal, title="misalignment (measured − ideal) and the identified model")
        plot_convergence(pso, staging / "convergence.png", ylabel="Eq. 13 fitness [rad]")
    print(f"flexcal identify: {len(selected)} sources, fit RMS {fit_rms * 1e6:.3g} urad, max "
          f"{summary['fit_max_urad']:.3g} urad, {wall_s:.1f} s; wrote {args.out}/report.json, report.md, fit.png, "
          f"convergence.png")
    return 0
