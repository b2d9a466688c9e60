"""``flexcal diagnose``: where the sim-to-real gap of a measurement lies, which unmodelled
effect causes it, and how far it shrinks once that effect is added (docs/diagnosis.md).

Writes DIR/report.json (``ranking``, ``top_effect``, ``where``, ``noise_floor_urad`` and the
evidence), DIR/report.md and the fmt3 residual.png (held-out residual before/after),
strata.png (residual RMS per stratum), heldout.png (held-out RMS per candidate).

    flexcal diagnose curves.csv --out runs/diagnosis
    flexcal diagnose --data curves.csv --out runs/diagnosis     # the same, spelled as verify/identify take it

A measurement on a ``flexcal design`` trajectory is read with its legs as the design wrote
them (the held-out folds) and its travel directions from the inputs. When most held-out
postures are measured in no other leg (one pass of a designed trajectory), the held-out
scores extrapolate the baseline: the command warns and the report says how many
(``heldout.share_not_repeated``); measure the trajectory twice (docs/diagnosis.md).

The baseline model is the calibration commands' default (the consistent model with quadratic
dimension terms) since session 28; ``--model second-order`` gives the baseline of the earlier
figures. A ``--null`` file must have been measured with the same model (its ``baseline``).
"""

from __future__ import annotations

import argparse

import numpy as np

from ..runs.settings import BaselineSettings
from .options import MODEL_DEFAULTS

__all__ = ["configure", "run", "EXAMPLES", "DEFAULT_CONFIG"]

_BASELINE = BaselineSettings()
# The baseline is the calibration commands' model (MODEL_DEFAULTS) since session 28: the
# second-order model it was before leaves its own form error at a design's postures, which a
# diagnosis reads as an effect (docs/diagnosis.md, "Issue 28 results (session 27)")
DEFAULT_CONFIG = {**MODEL_DEFAULTS, "particles": _BASELINE.particles, "iterations": _BASELINE.iterations}

EXAMPLES = ("flexcal diagnose curves.csv --out runs/diagnosis",
            "flexcal diagnose --data runs/t/curves.csv --out runs/d",
            "flexcal truth --scenario table1 --provider analytic --noise-urad 0.5 --out runs/t && "
            "flexcal diagnose runs/t/curves.csv --out runs/d")


def configure(parser: argparse.ArgumentParser) -> None:
    from .options import add_out, add_seed
    from .options import add_model_options

    parser.add_argument("data", metavar="DATA.csv", nargs="?",
                        help="measurement CSV (format: flexcal.validation.measurements)")
    parser.add_argument("--data", dest="data_option", metavar="CSV",
                        help="the measurement CSV, as verify and identify take it (instead of DATA.csv)")
    from .options import add_unit_check_option

    add_unit_check_option(parser)
    from .options import add_mount

    add_mount(parser, what="the data's mount (the sidecar's; the differences are listed)")
    add_seed(parser, what="the baseline calibration's optimizer", default=0)
    parser.add_argument("--particles", type=int, help="PSO particles of each baseline start (default %(default)s)")
    parser.add_argument("--iterations", type=int, help="PSO iterations of each baseline start (default %(default)s)")
    add_model_options(parser)
    parser.add_argument("--null", metavar="JSON",
                        help="the null of the file's trajectory: each term's held-out gain on `none` files along it "
                             "(DIR/null.json of flexcal diagnose-benchmark --trajectory ...); a term must gain 3x its "
                             "own there as well (docs/diagnosis.md, Null of the trajectory)")
    add_out(parser, what="report.json, report.md, residual.png, strata.png, heldout.png")


def _form_floor(measurement, space, residual) -> dict:
    """The baseline model's form floor from the sidecar's presets (the diagnosis itself never
    reads the sidecar); residual (n, 3) [rad] measured - baseline."""
    from ..runs.form_floor import model_form_floor, not_available, truth_from_measurement

    truth = truth_from_measurement(measurement, space)
    return not_available() if truth is None else model_form_floor(truth, measurement.inputs, space,
                                                                  fit_residual=-residual)


def data_path(args: argparse.Namespace) -> str:
    """The measurement file of ``DATA.csv`` or ``--data`` (one of them)."""
    given = [path for path in (args.data, getattr(args, "data_option", None)) if path]
    if not given:
        raise ValueError("no measurement: flexcal diagnose DATA.csv --out DIR (or --data DATA.csv)")
    if len(given) == 2 and given[0] != given[1]:
        raise ValueError(f"two measurements, {given[0]} and --data {given[1]}: give one")
    return given[0]


# a held-out scoring where most held-out postures are in no training leg extrapolates the
# baseline (one pass of a designed trajectory: 1.0); the standard trajectory twice: 0.0
EXTRAPOLATION_WARNING_SHARE = 0.5


def run(args: argparse.Namespace) -> int:
    import logging
    from functools import partial

    from .common import show_progress
    from ..diagnosis.diagnose import check_measurement, run_diagnosis
    from ..diagnosis.baseline import BaselineSettings, calibrate_baseline
    from ..executor import usable_cores
    from ..diagnosis.plots import plot_heldout, plot_residual, plot_strata
    from ..output import staged_output, write_report
    from ..reports.diagnose import fmt3, markdown
    from .opening import open_calibration

    if args.particles < 2 or args.iterations < 1:
        raise ValueError("--particles must be >= 2 and --iterations >= 1")
    from ..diagnosis.null import check_null_baseline, read_null
    from .opening import check_model_options, model_key

    check_model_options(args)
    null = read_null(args.null) if args.null else None
    if null is not None:
        check_null_baseline(null, model_key(args), f"--null {args.null}")
    # the measurement checked before the model's FEM correction (~30 s cold)
    opening = open_calibration(args, progress=show_progress(args), data_path=data_path(args), check=check_measurement)
    measurement, space = opening.measurement, opening.space
    # the baseline's swarm and polish run the model on every usable core (the same bits at any count)
    baseline = partial(calibrate_baseline, space=space, n_threads=usable_cores(),
                       settings=BaselineSettings(particles=args.particles, iterations=args.iterations))
    diagnosis = run_diagnosis(measurement, baseline=baseline, rng=args.seed, progress=show_progress(args), null=null)
    report = diagnosis.report
    report["baseline"]["model_stiffness"] = args.model_stiffness
    report["baseline"]["second_order"] = bool(args.second_order)
    report["baseline"]["model"] = args.model
    report["model_form_floor"] = _form_floor(measurement, space, diagnosis.residual)
    share = report["heldout"]["share_not_repeated"]
    if share > EXTRAPOLATION_WARNING_SHARE:
        logging.getLogger("flexcal.diagnose").warning(
            f"{100 * share:.0f} % of the held-out points are at postures no other leg measures (one pass of a designed "
            f"trajectory?): the held-out scores extrapolate the baseline and may name a wrong effect; measure the "
            f"trajectory twice (docs/diagnosis.md, Designed trajectory)")
    with staged_output(args.out, replace=args.force) as staging:
        write_report(staging, report)
        (staging / "report.md").write_text(markdown(report))
        plot_residual(staging / "residual.png", diagnosis, measurement.leg)
        plot_strata(staging / "strata.png", report["where"]["strata"], np.asarray(report["noise_floor_per_angle_urad"]))
        plot_heldout(staging / "heldout.png", report["ranking"])
    if show_progress(args):
        print(f"flexcal diagnose: top effect {report['top_effect']} (confidence {report['confidence']}), held-out RMS "
              f"{fmt3(report['how_far']['heldout_rms_before_urad'])} -> {fmt3(report['how_far']['heldout_rms_after_urad'])}"
              f" urad, noise floor {report['noise_floor_urad']:.3g} urad; wrote {args.out}/report.json")
    return 0
