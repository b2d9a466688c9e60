"""``flexcal design``: choose the calibration postures before measuring (D-optimal).

Writes DIR/trajectory.csv (columns point, leg, xa1_mm, xa2_mm, xa3_mm: the file that
``flexcal truth``, ``verify``, ``sensitivity`` and ``identify`` take with ``--trajectory``, and the
order in which to measure a real mount), DIR/report.json, DIR/report.md and design.png (the
expected standard error of each source with the designed and the standard trajectory).

The design point is the prior mean (every source mid-range: Eq. 9), or with ``--at
REPORT`` the values a previous ``flexcal verify``/``identify`` identified (sequential design:
the information of a clearance or hysteresis source depends on the drive loads, which
depend on the sources themselves); the prior is the paper's ranges scaled by ``--prior-scale``, the noise ``--noise-urad``; with ``--inadequacy analytic``
(default) the model's own error at each candidate posture, measured once against the
analytic virtual prototype at the nominal design, is added to the noise, so that postures
where the model is known to be off (large combined rotations) weigh less, and the
candidates where it exceeds the upper quartile of its error over the standard trajectory's
postures are avoided; report.md says how many and why (``flexcal.calibration.design``).
``--region box|hull`` draws the candidates in the standard trajectory's input box or the hull of
its postures, ``--criterion I`` minimizes the mean prediction variance over that box instead of
maximizing log det M, ``--criterion drives`` the sum of the nine drive sources' expected variances, each
over its paper Table 1 figure squared (x0 2.7 um, CL 0.02 mm, mu 1.3 % of its value at the design
point: issue #28's largest-error test; A-optimal, ``calibration.design.figure_weights``),
``--keep-standard K`` measures the K-point standard trajectory first and designs the rest (report.md says which postures were kept and why); none of them beat the standard
trajectory on table1 seed 1 (FEM prototype, docs/calibration.md 10), and on `paper` with ``--at``
stage 1's estimate and ``--model consistent`` ``--keep-standard 41`` beat it on 2 of 3 seeds
(docs/calibration.md 11, "A 77-point design that keeps the standard sweeps"), so the default
stays the D-optimal design over the whole workspace.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from .options import MODEL_DEFAULTS, add_out, add_scenario

__all__ = ["configure", "run", "EXAMPLES", "DEFAULT_CONFIG"]

EXAMPLES = (
    "flexcal design --out runs/design                                  # 77 postures from 2000 candidates",
    "flexcal design --scenario paper --points 61 --out runs/design-paper",
    "flexcal truth --scenario table1 --trajectory runs/design/trajectory.csv --noise-urad 0.5 --out runs/t1",
    "flexcal design --at runs/first-verify/report.json --out runs/design-2   # design at the identified values",
)
MODEL_ERROR_QUANTILE = 0.75  # candidates whose expected model error exceeds this quantile of the standard
# trajectory's are avoided (the report says how many and why)
DEFAULT_CONFIG = {"points": 77, "candidates": 2000, "noise_urad": 0.5, "prior_scale": 1.0, "points_per_leg": 11,
                  "design_seed": 0, "inadequacy": "analytic", "at": "", "scenario": "table1", "region": "workspace",
                  "criterion": "D", "keep_standard": 0, **MODEL_DEFAULTS}
KEPT_WHY = ("the standard trajectory's one-actuator sweeps are measured first, as they are: there the model's form "
            "error is smallest (its floor on the standard trajectory is a fraction of the designs'), so the drive "
            "offsets x0 they carry are not biased by a form error the fit absorbs; the designed postures add only "
            "the information the sweeps lack (the nuts in their gaps: the clearances and hysteresis)")
N_PREDICTION = 400  # postures drawn in the standard trajectory's input box whose prediction variance the I-criterion averages


def configure(parser: argparse.ArgumentParser) -> None:
    from .options import add_model_options

    add_scenario(parser, required=False)
    from .options import add_mount

    add_mount(parser)
    parser.add_argument("--points", type=int, metavar="N", help="postures to measure, the zero posture included "
                                                                 "(default %(default)s)")
    parser.add_argument("--candidates", type=int, metavar="N",
                        help="candidate postures drawn inside the mount's workspace (reference: +-1/+-5/+-3 mrad; default "
                             "%(default)s)")
    parser.add_argument("--noise-urad", type=float, metavar="S", help="sensor noise per channel [urad] (default "
                                                                       "%(default)s)")
    parser.add_argument("--prior-scale", type=float, metavar="S",
                        help="prior std as a multiple of each range's spread (default %(default)s)")
    parser.add_argument("--points-per-leg", type=int, metavar="N",
                        help="postures per leg; legs are the held-out folds of the identification (default "
                             "%(default)s)")
    parser.add_argument("--at", metavar="REPORT",
                        help="design at the values identified in this report.json (flexcal verify / identify) "
                             "instead of the prior mean")
    parser.add_argument("--design-seed", type=int, metavar="N", help="seed of the candidate draw (default %(default)s)")
    parser.add_argument("--inadequacy", choices=("analytic", "none"),
                        help="add the model's error at each candidate (against the analytic prototype at the nominal "
                             "design) to the noise and avoid the candidates where it exceeds the upper quartile of "
                             "its error on the standard trajectory (default %(default)s)")
    parser.add_argument("--region", choices=("workspace", "box", "hull"),
                        help="where candidates are drawn: the whole angular workspace, the standard trajectory's "
                             "actuator-input box (+-its strokes), or the convex hull of its postures (the "
                             "octahedron of one-actuator strokes) (default %(default)s)")
    parser.add_argument("--criterion", choices=("D", "I", "drives"),
                        help="D: parameter volume (log det M); I: mean prediction variance over the standard "
                             "trajectory's input box; drives: the sum of the nine drive sources' expected variances, "
                             "each over its paper Table 1 figure squared (A-optimal; issue #28's test) (default "
                             "%(default)s)")
    parser.add_argument("--keep-standard", type=int, metavar="K",
                        help="measure the standard trajectory of K points first and design only the rest "
                             "(0: none; default %(default)s)")
    add_model_options(parser)
    add_out(parser, what="trajectory.csv, report.json, report.md, design.png")


def _check(args: argparse.Namespace) -> None:
    if args.points < 2:
        raise ValueError(f"--points={args.points} must be >= 2")
    if args.candidates < args.points:
        raise ValueError(f"--candidates={args.candidates} must be >= --points={args.points}")
    if not args.noise_urad > 0:
        raise ValueError(f"--noise-urad={args.noise_urad} must be > 0 (the design weighs postures by it)")
    if not args.prior_scale > 0:
        raise ValueError(f"--prior-scale={args.prior_scale} must be > 0")
    if args.points_per_leg < 1:
        raise ValueError(f"--points-per-leg={args.points_per_leg} must be >= 1")
    if not 0 <= args.keep_standard < args.points:
        raise ValueError(f"--keep-standard={args.keep_standard} must be >= 0 and < --points={args.points}")
    if args.at:
        from pathlib import Path

        if not Path(args.at).is_file():
            raise ValueError(f"--at {args.at}: no such file (a flexcal verify/identify report.json)")


def _inadequacy(space, scenario_space, progress: bool):
    """inputs (k, 3) -> (k, 3) [rad]: model minus analytic prototype at the nominal design."""
    import dataclasses

    from flexcal.calibration.problem import CalibrationProblem

    from ..prototype.segments import analytic_provider
    from ..prototype.scenario import load_scenario
    from ..prototype.truth import make_truth

    def delta(inputs: np.ndarray) -> np.ndarray:
        nominal = load_scenario("nominal", space=scenario_space)
        nominal = dataclasses.replace(nominal, inputs=inputs, leg=np.ones(len(inputs), int))
        measured = make_truth(nominal, analytic_provider(), progress=progress).measurement.angles
        problem = CalibrationProblem(space=space, inputs=inputs, angles=measured)
        return np.abs(problem.residuals(space.to_unit(space.nominal_vector)[None])[0].reshape(-1, 3))

    return delta


def drive_figures(space, x_design: np.ndarray) -> dict[str, float]:
    """The paper's Table 1 figure of each drive source [SI] (``runs.verify.PAPER_DRIVE_FIGURES``): x0 its
    largest error [m], CL [m], mu its relative error times the source's value at the design point
    x_design (n_active,) [unit box] (mu is dimensionless)."""
    from flexcal.model.parameters import DRIVE_SOURCE_NAMES

    from ..runs.verify import PAPER_DRIVE_FIGURES

    values = space.from_unit(x_design)
    si = {"x0": 1e-6, "CL": 1e-3}  # um, mm -> m
    figures = {}
    for name in DRIVE_SOURCE_NAMES:
        symbol = name.split(".")[1]
        figures[name] = PAPER_DRIVE_FIGURES[symbol] * si[symbol] if symbol in si else (
            PAPER_DRIVE_FIGURES[symbol] / 100 * abs(values[space.names.index(name)]))
    return figures


def design_point(path: str, space) -> np.ndarray:
    """Unit-box values (n_active,) of the sources identified in a report.json."""
    from .opening import report_values

    return space.to_unit(report_values(path, space, "--at")[space.active_indices])


def run(args: argparse.Namespace) -> int:
    from flexcal.calibration.design import candidate_inputs, design_trajectory, figure_weights
    from flexcal.calibration.estimation import FD_STEP, uniform_prior
    from flexcal.calibration.polish import batched_jacobian_fd
    from flexcal.calibration.problem import CalibrationProblem
    from flexcal.model.assembly import mechanism_matrices
    from flexcal.model.trajectory import standard_trajectory

    from .common import show_progress
    from .opening import calibration_model
    from ..executor import usable_cores
    from ..output import staged_output, write_report
    from ..prototype.scenario import load_scenario
    from ..reports.design import markdown, plot_design

    _check(args)
    progress = show_progress(args)
    start = time.perf_counter()
    from .options import mount_option

    scenario = load_scenario(args.scenario, mount=mount_option(args))
    space = calibration_model(args, scenario.space.mechanism, progress=progress)
    prior = uniform_prior(space.n_params, args.prior_scale)
    x_design = design_point(args.at, space) if args.at else prior.mean

    cores = usable_cores()  # a Jacobian's 46 candidates on every usable core (the same bits, ``model.forward``)

    def jacobian(inputs: np.ndarray) -> np.ndarray:
        problem = CalibrationProblem(space=space, inputs=inputs, angles=np.zeros_like(inputs), n_threads=cores)
        return batched_jacobian_fd(problem.residuals, x_design, step=FD_STEP)[0]

    gain = mechanism_matrices(space.nominal_full, space).input_gain[0, 3:, 3:]
    standard = standard_trajectory(space.mechanism, n_points=77)
    reference = standard.inputs
    box = np.asarray(standard.amplitudes, float)  # [m] the standard trajectory's strokes
    say = (lambda text: print(f"design: {text}")) if progress else None
    inadequacy = _inadequacy(space, scenario.space, False) if args.inadequacy == "analytic" else None
    # never where the model is known to be worse than on most of the standard trajectory
    # (calibration.design): the upper quartile of the expected error over its own postures (its
    # largest, 15.6 urad on table1 at one stroke end, left all but 7 of 2000 candidates in)
    limit = None if inadequacy is None else float(np.quantile(np.max(inadequacy(reference), axis=1),
                                                              MODEL_ERROR_QUANTILE))
    kept = standard_trajectory(space.mechanism, n_points=args.keep_standard) if args.keep_standard else None
    weights = (figure_weights(space.names, space.upper - space.lower, drive_figures(space, x_design))
               if args.criterion == "drives" else None)
    design = design_trajectory(jacobian, gain, np.asarray(space.mechanism.workspace), reference, n_points=args.points,
                               n_candidates=args.candidates, noise=args.noise_urad * 1e-6,
                               prior_precision=prior.precision, prior_scale=args.prior_scale,
                               points_per_leg=args.points_per_leg, rng=args.design_seed, progress=say,
                               inadequacy=inadequacy, max_inadequacy=limit, region=args.region,
                               box=None if args.region == "workspace" else box, criterion=args.criterion,
                               prediction_inputs=candidate_inputs(box, N_PREDICTION, "box", args.design_seed + 1),
                               variance_weights=weights,
                               fixed_inputs=kept.inputs if kept is not None else None,
                               fixed_leg=kept.leg if kept is not None else None)
    wall = time.perf_counter() - start
    report = _report(design, space, args, wall, weights)
    with staged_output(args.out, replace=args.force) as staging:
        _write_trajectory(staging / "trajectory.csv", design)
        write_report(staging, report)
        (staging / "report.md").write_text(markdown(report))
        plot_design(staging / "design.png", design, space.names)
    q, r = design.quality, design.reference_quality
    print(f"flexcal design: {args.points} postures from {args.candidates} candidates in {wall:.1f} s; "
          f"log det M {q.d_criterion:.1f} (standard trajectory {r.d_criterion:.1f}), rank {q.rank} ({r.rank}); "
          f"wrote {args.out}/trajectory.csv")
    return 0


def _quality(q) -> dict:
    return {"log_det_information": q.d_criterion, "d_efficiency": q.d_efficiency, "sigma_min": q.sigma_min,
            "condition_number": q.condition_number if np.isfinite(q.condition_number) else None,
            "rank": q.rank, "expected_std_of_range": q.expected_std.tolist(),
            "n_sources_below_1pct": int(np.sum(q.expected_std <= 0.01))}


CRITERION_TEXT = {
    "D": "D-optimal: log det (W^T W + prior precision)",
    "I": "I-optimal: mean prediction variance over the standard trajectory's input box, trace((W^T W + prior "
         "precision)^-1 A)",
    "drives": "A-optimal on the drive sources: trace((W^T W + prior precision)^-1 A), A diagonal (range / paper "
              "Table 1 figure)^2 on the nine drive sources (x0 2.7 um, CL 0.02 mm, mu 1.3 % of its value at the "
              "design point), zero elsewhere: the sum of their expected (standard error / figure)^2",
}


def _drives_criterion(design, weights) -> dict | None:
    """trace(M^-1 A) of the design and of the standard trajectory (A diagonal: sum of weight *
    expected variance), and each drive source's expected error over its figure (None: no A)."""
    if weights is None:
        return None
    w = np.diag(weights)
    out = {}
    for key, q in (("designed", design.quality), ("standard_trajectory", design.reference_quality)):
        out[key] = {"trace": float(np.sum(w * q.expected_std ** 2)),
                    "max_std_over_figure": float(np.sqrt(np.max(w * q.expected_std ** 2)))}
    return out


def _report(design, space, args, wall: float, weights=None) -> dict:
    return {
        "n_points": int(design.inputs.shape[0]), "n_candidates": int(design.candidates.shape[0]),
        "noise_urad": design.noise * 1e6, "prior_scale": design.prior_scale, "scenario": args.scenario,
        "design_seed": args.design_seed, "inadequacy": args.inadequacy, "region": args.region,
        "criterion_name": args.criterion, "keep_standard": args.keep_standard,
        "design_point": args.at or "prior mean (every source mid-range)",
        "inadequacy_rms_urad": None if design.inadequacy is None else float(np.sqrt(np.mean(design.inadequacy ** 2))
                                                                            * 1e6),
        "criterion": CRITERION_TEXT[args.criterion] + ", W = model Jacobian / noise on the unit box, at the design "
                     "point",
        "drives_criterion": _drives_criterion(design, weights),
        "avoided": _avoided(design),
        "kept": _kept(design, args.keep_standard),
        "names": list(space.names), "designed": _quality(design.quality),
        "standard_trajectory": _quality(design.reference_quality), "wall_s": wall,
        "note": "sigma_min and condition number are those of the data-only W (no prior); a rank below 45 means "
                "some combinations stay at their prior",
    }


def _avoided(design) -> dict | None:
    """Which candidate postures the design did not offer and why (None: no inadequacy)."""
    if design.avoided is None:
        return None
    error = np.abs(design.inadequacy).max(axis=1)  # [rad] the worst angle at each candidate
    n = int(design.avoided.sum())
    kept = ~design.avoided
    return {"n_avoided": n, "n_candidates": int(design.avoided.size),
            "max_model_error_urad": design.max_inadequacy * 1e6,
            "why": "the model's expected error there (against the analytic virtual prototype at the nominal design) "
                   "exceeds what it reaches on 75 % of the standard trajectory's own postures: a form error the fit "
                   "would absorb into the sources as a bias the error bars of the noise do not carry",
            "avoided_model_error_urad": {"median": float(np.median(error[design.avoided]) * 1e6) if n else None,
                                         "max": float(error[design.avoided].max() * 1e6) if n else None},
            "kept_inputs_mm_max_abs": (np.abs(design.candidates[kept]).max(axis=0) * 1e3).tolist(),
            "avoided_inputs_mm_median_abs": (np.median(np.abs(design.candidates[design.avoided]), axis=0) * 1e3).tolist()
            if n else None}


def _kept(design, n_kept: int) -> dict | None:
    """Which postures were measured as they are, without choice, and why (None: none but the zero posture)."""
    if not n_kept:
        return None
    kept, chosen = design.inputs[:n_kept], design.inputs[n_kept:]
    return {"n_kept": n_kept, "n_designed": int(chosen.shape[0]),
            "kept_inputs_mm_max_abs": (np.abs(kept).max(axis=0) * 1e3).tolist(),
            "designed_inputs_mm_max_abs": (np.abs(chosen).max(axis=0) * 1e3).tolist(),
            "why": KEPT_WHY}


def _write_trajectory(path, design) -> None:
    from ..output import atomic_path

    with atomic_path(path) as tmp:
        rows = ["point,leg,xa1_mm,xa2_mm,xa3_mm"]
        for k, (x, leg) in enumerate(zip(design.inputs * 1e3, design.leg), start=1):
            rows.append(f"{k},{int(leg)},{x[0]:.9f},{x[1]:.9f},{x[2]:.9f}")
        tmp.write_text("\n".join(rows) + "\n")
