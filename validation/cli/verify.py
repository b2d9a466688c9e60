"""``flexcal verify``: the paper's Section 3.3 regression run.

Prototype curves (or ``--data FILE``) -> identification (``--method map``: all sources with
a cross-validated prior, the default; ``free``; ``paper``: Sobol screening + improved PSO)
-> DIR/report.json, DIR/report.md and figures: fit.png (Fig. 7a-c), residuals.png (Fig. 7e),
calibration.png (identified error against its standard error, synthetic data), with
``--method paper`` also convergence.png (Fig. 7d) and sensitivity.png (Fig. 5);
curves.csv/json (the data).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from .options import CALIBRATION_DEFAULTS, add_calibration_options, add_error_bar_options, add_out
from .options import prior_scale_option

__all__ = ["configure", "run", "EXAMPLES", "DEFAULT_CONFIG"]

EXAMPLES = (
    "flexcal verify --scenario table1 --out runs/table1          # paper Sec. 3.3, ~1 min with a warm FEM cache",
    "flexcal design --out runs/design && flexcal verify --scenario table1 --trajectory runs/design/trajectory.csv "
    "--noise-urad 0.5 --out runs/t1-designed",
    "flexcal verify --scenario table1 --method paper --out runs/paper   # the paper's Sobol screening + PSO",
    "flexcal verify --data curves.csv --remove-offset --out runs/measured",
    "flexcal verify --scenario table1 --particles 60 --iterations 40 --sobol-n 128 --out runs/quick",
    "flexcal verify --print-config > verify.toml; flexcal verify --config verify.toml --scenario table1 --out runs/t1",
    "flexcal report runs/table1                                   # -> runs/table1/report.html",
)
DEFAULT_CONFIG = {"provider": "fem", "start": "", **CALIBRATION_DEFAULTS}


def configure(parser: argparse.ArgumentParser) -> None:
    from .options import add_source_options

    add_source_options(parser)
    add_calibration_options(parser)
    add_error_bar_options(parser)
    parser.add_argument("--start", metavar="REPORT",
                        help="--method map/free: start every fit at the values identified in this report.json "
                             "(flexcal verify / identify; e.g. the standard trajectory's run before a designed one, "
                             "whose large strokes can trap a fit from the prior mean: docs/calibration.md 11) "
                             "instead of the prior mean")
    add_out(parser, what="report.json, report.md, fit/convergence/residuals/sensitivity PNGs, curves.csv")


def run(args: argparse.Namespace) -> int:
    from flexcal.calibration.pso_settings import PSOSettings

    from .options import check_sobol_options, error_budget_option, profile_option
    from ..measurements import write_measurement
    from ..output import staged_output, write_report
    from ..reports.verify import verify_lines, verify_markdown, write_verify_figures
    from .opening import open_calibration
    from ..runs.verify import VerifySettings, run_verify

    if args.particles < 2 or args.iterations < 1:
        raise ValueError(f"--particles={args.particles} must be >= 2 and --iterations={args.iterations} >= 1")
    check_sobol_options(args)
    if args.start and args.method == "paper":
        raise ValueError("--start sets where the map/free fits start; --method paper's swarm has no start point")
    if args.start and not Path(args.start).is_file():  # before the model's (possibly cold FEM) build
        raise ValueError(f"--start {args.start}: no such file (a flexcal verify/identify report.json)")
    settings = VerifySettings(sobol_n=args.sobol_n, sobol_threshold=args.sobol_threshold, seed=args.calibration_seed,
                              polish=args.polish, remove_offset=args.remove_offset, method=args.method,
                              prior_scale=prior_scale_option(args),
                              noise_urad=args.noise_urad if args.noise_urad else None,
                              pso=dataclasses.replace(PSOSettings(), n_particles=args.particles,
                                                      max_iterations=args.iterations))
    opening = open_calibration(args, progress=not args.quiet)
    measurement, space = opening.measurement, opening.space
    settings = dataclasses.replace(settings, profile=profile_option(args, measurement.metadata))
    if args.start:
        from .opening import report_values

        settings = dataclasses.replace(settings, start=tuple(report_values(args.start, space, "--start").tolist()))
    budget = error_budget_option(args, space, measurement.inputs, progress=not args.quiet)
    result = run_verify(measurement, space, settings, presets=opening.presets, truth=opening.truth,
                        progress=not args.quiet, budget=budget)
    tied = {"fem": " (its segments joined through the cut fields)",
            "fem-rigid": " (its segments joined rigidly at the cuts: fem-rigid)"}.get(args.model_stiffness, "")
    result.report["model_stiffness"] = (f"closed-form chains scaled by FEM factors at the nominal design{tied} "
                                        "(docs/model.md 7)" if space.compliance_factors else "closed-form (paper Eq. 1)")
    result.report["model_second_order"] = bool(space.second_order)
    from ..runs.form_floor import model_description

    result.report["model"] = model_description(space)
    with staged_output(args.out, replace=args.force) as staging:
        write_report(staging, result.report)
        (staging / "report.md").write_text(verify_markdown(result.report))
        write_measurement(staging / "curves.csv", measurement)
        write_verify_figures(result, measurement, staging)
    print("\n".join(verify_lines(result.report, args.out)))
    return 0
