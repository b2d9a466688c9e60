"""``flexcal sensitivity``: Sobol screening of the 45 error sources alone (paper Sec. 3.1).

The same screening as ``flexcal verify``'s first step (total and first-order Sobol
indices of the model's deviation from the ideal small-deflection model, overall and per
angle, along the measurement's inputs), on a measurement CSV or on a scenario's synthetic
curves, without the identification. Writes DIR/report.json (indices, ranked table, the
sources ``verify`` would identify), DIR/report.md and DIR/sensitivity.png (Fig. 5).
"""

from __future__ import annotations

import argparse

from .options import add_out, add_source_options, calibration_defaults, check_sobol_options

__all__ = ["configure", "run", "screen", "EXAMPLES", "DEFAULT_CONFIG"]

EXAMPLES = (
    "flexcal sensitivity --scenario table1 --out runs/sobol                 # N = 512: 24,064 model runs",
    "flexcal sensitivity --data curves.csv --sobol-n 128 --out runs/sobol-quick",
    "flexcal sensitivity --scenario table1 --provider analytic --sobol-n 64 --json --out runs/s",
)
DEFAULT_CONFIG = calibration_defaults("model", "model_stiffness", "second_order",
                                      "dimension_terms", "sobol_n", "sobol_threshold",
                                      "calibration_seed",
                                      provider="fem")


def configure(parser: argparse.ArgumentParser) -> None:
    add_source_options(parser)
    parser.add_argument("--sobol-n", type=int, metavar="N", help="Sobol base sample N (power of two; default %(default)s)")
    parser.add_argument("--sobol-threshold", type=float, metavar="S",
                        help="report the sources whose total index reaches S on any output (default %(default)s)")
    parser.add_argument("--calibration-seed", type=int, metavar="N", help="seed of the Sobol sample (default %(default)s)")
    from .options import add_model_options

    add_model_options(parser)
    add_out(parser, what="report.json, report.md, sensitivity.png")


def screen(measurement, space, *, n_base: int, seed: int, progress: bool):
    """Total Sobol indices of the deviation from the ideal model (as ``run_verify``)."""
    from flexcal.calibration.problem import CalibrationProblem
    from flexcal.calibration.sensitivity import sobol_indices

    from ..executor import usable_cores
    from ..progress import progress_bar, with_progress
    from ..runs.verify import OUTPUTS

    # the model's batches on every usable core (the same bits at any count, ``model.forward``)
    problem = CalibrationProblem(space=space, inputs=measurement.inputs, angles=measurement.angles,
                                 n_threads=usable_cores())
    with progress_bar(n_base * (space.n_params + 2), "Sobol", enabled=progress, unit="run") as bar:
        evaluate = with_progress(problem.deviation_from_ideal, bar)
        return sobol_indices(evaluate, [[0.0, 1.0]] * space.n_params, n_base, seed=seed, names=space.names,
                             outputs=OUTPUTS, chunk_size=max(64, n_base))


def run(args: argparse.Namespace) -> int:
    from flexcal.calibration.sensitivity import ranked_table, select_parameters

    from .common import show_progress
    from .opening import open_calibration
    from ..output import staged_output, write_report
    from ..reports.sensitivity import sensitivity_markdown, write_sensitivity_figure
    from flexcal.model.parameters import DRIVE_SOURCE_NAMES

    check_sobol_options(args)
    progress = show_progress(args)
    opening = open_calibration(args, progress=progress)
    measurement, space = opening.measurement, opening.space
    sobol = screen(measurement, space, n_base=args.sobol_n, seed=args.calibration_seed, progress=progress)
    selected = select_parameters(sobol, threshold=args.sobol_threshold, always=DRIVE_SOURCE_NAMES)
    report = {
        "summary": {"n_points": measurement.n_points, "n_base": sobol.n_base, "n_evaluations": sobol.n_evaluations,
                    "n_selected": len(selected), "most_sensitive": ranked_table(sobol, 0)[0]["name"],
                    "sobol_threshold": args.sobol_threshold, "seed": args.calibration_seed},
        "config": args.config,
        "selected": list(selected),
        "names": list(sobol.names), "outputs": list(sobol.outputs),
        "ST": sobol.ST, "ST_conf": sobol.ST_conf, "S1": sobol.S1, "S1_conf": sobol.S1_conf,
        "ranked_overall": ranked_table(sobol, 0),
    }
    with staged_output(args.out, replace=args.force) as staging:
        write_report(staging, report)
        (staging / "report.md").write_text(sensitivity_markdown(
            sobol, n_points=measurement.n_points, seed=args.calibration_seed, threshold=args.sobol_threshold,
            selected=selected))
        write_sensitivity_figure(staging, sobol)
    top = ", ".join(f"{r['name']} {r['ST']:.3f}" for r in ranked_table(sobol, 0)[:5])
    print(f"flexcal sensitivity: {sobol.n_evaluations} model runs; top total indices {top}; "
          f"{len(selected)} sources selected; wrote {args.out}/report.json, report.md, sensitivity.png")
    return 0
