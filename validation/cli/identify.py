"""``flexcal identify``: identification alone (paper Sec. 3.2, Eq. 13).

Identifies the chosen error sources (``--sources``) from a measurement CSV (or a scenario's
synthetic curves), the other sources staying at nominal, through the same pipeline as
``flexcal verify`` (``runs.verify.run_verify`` with ``VerifySettings.sources``): by default
the paper's improved multi-subgroup PSO with the least-squares polish (``--method paper``;
no Sobol screening: ``flexcal sensitivity`` gives the ranking, ``flexcal verify`` runs
both), or MAP / free least squares (``--method map|free``) with standard errors. Writes
DIR/report.json (identified values and standard errors, the errors against the presets when
the data are synthetic, fit, identifiability), DIR/report.md, DIR/fit.png and (PSO)
DIR/convergence.png.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from .options import add_out, calibration_defaults
from .options import add_error_bar_options, add_source_options

__all__ = ["configure", "run", "parse_sources", "EXAMPLES", "DEFAULT_CONFIG"]

EXAMPLES = (
    "flexcal identify --scenario table1 --out runs/ident                  # the nine Table 1 drive sources",
    "flexcal identify --data curves.csv --sources D1.x0,D1.CL,D1.mu --remove-offset --out runs/d1",
    "flexcal identify --scenario table1 --provider analytic --particles 40 --iterations 20 --out runs/quick",
)
DEFAULT_CONFIG = calibration_defaults("model", "model_stiffness", "second_order",
                                      "dimension_terms", "particles", "iterations", "polish",
                                      "remove_offset", "calibration_seed", "prior_scale", provider="fem",
                                      sources="table1", method="paper")


def configure(parser: argparse.ArgumentParser) -> None:
    from .options import add_identification_options, add_method_options, add_model_options

    add_source_options(parser)
    parser.add_argument("--sources", metavar="NAMES",
                        help="comma-separated error sources to identify (docs/parameters.md), 'table1' (the nine "
                             "drive sources x0, CL, mu) or 'all' (default %(default)s)")
    add_method_options(parser)
    add_identification_options(parser)
    add_model_options(parser)
    parser.add_argument("--calibration-seed", type=int, metavar="N", help="seed of the PSO (default %(default)s)")
    add_error_bar_options(parser)
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
    from flexcal.calibration.pso_settings import PSOSettings
    from flexcal.model.parameters import parameter_space

    from ..output import staged_output, write_report
    from ..reports.form_floor import form_floor_line
    from ..reports.identify import identify_markdown, write_identify_figures
    from .opening import open_calibration
    from ..runs.verify import VerifySettings, run_verify
    from .common import show_progress
    from .options import error_budget_option, prior_scale_option, profile_option

    if args.particles < 2 or args.iterations < 1:
        raise ValueError(f"--particles={args.particles} must be >= 2 and --iterations={args.iterations} >= 1")
    selected = parse_sources(args.sources, parameter_space().names)
    progress = show_progress(args)
    settings = VerifySettings(method=args.method, prior_scale=prior_scale_option(args), sources=selected,
                              polish=args.polish, seed=args.calibration_seed, remove_offset=args.remove_offset,
                              noise_urad=args.noise_urad if args.noise_urad else None,
                              pso=dataclasses.replace(PSOSettings(), n_particles=args.particles,
                                                      max_iterations=args.iterations))
    from flexcal.calibration.pipeline import check_determined

    opening = open_calibration(args, progress=progress,
                               check=lambda measurement: check_determined(measurement.n_points, len(selected)))
    measurement, presets, truth, space = opening.measurement, opening.presets, opening.truth, opening.space
    settings = dataclasses.replace(settings, profile=profile_option(args, measurement.metadata))
    start = time.perf_counter()
    # bars on stderr for the long loops (PSO iterations, least-squares fits); identify prints its own summary
    budget = error_budget_option(args, space, measurement.inputs, progress=progress)
    result = run_verify(measurement, space, settings, presets=presets, truth=truth, progress=progress,
                        log=lambda *a, **k: None, budget=budget)
    wall_s = time.perf_counter() - start
    verified = result.report
    rows = verified["parameters"]
    fit_rms = verified["fit_rms_urad"] * 1e-6
    ident = verified["identifiability"]
    summary = {"n_points": measurement.n_points, "n_identified": len(selected), "method": args.method,
               "fit_rms_urad": verified["fit_rms_urad"], "fit_max_urad": verified["fit_max_urad"],
               "fitness_eq13_urad": verified["fitness_eq13_urad"], "n_evaluations": verified["n_evaluations"],
               "rank": int(ident["rank"]), "seed": args.calibration_seed}
    if "condition_number" in ident:
        summary["condition_number"] = float(ident["condition_number"])
    report = {
        "summary": summary, "config": args.config, "selected": list(selected), "parameters": rows,
        "identifiability": ident,
        "pso": verified.get("pso"), "polish": verified.get("polish"),
        "estimation": verified.get("estimation"), "base_parameters": verified.get("base_parameters"),
        "noise_urad": verified["noise_urad"], "noise_source": verified["noise_source"],
        "offset_removed": bool(args.remove_offset),
        "model_form_floor": verified["model_form_floor"],
        "wall_s": wall_s,
    }
    with staged_output(args.out, replace=args.force) as staging:
        write_report(staging, report)
        (staging / "report.md").write_text(identify_markdown(report, has_pso=result.pso is not None,
                                                             has_preset=presets is not None))
        write_identify_figures(staging, result, measurement, space)
    print(f"flexcal identify: {len(selected)} sources ({args.method}), fit RMS {fit_rms * 1e6:.3g} urad, max "
          f"{summary['fit_max_urad']:.3g} urad, {wall_s:.1f} s; wrote {args.out}/report.json, report.md, fit.png"
          + (", convergence.png" if result.pso is not None else ""))
    print("  " + form_floor_line(verified["model_form_floor"]))
    return 0
