"""``flexcal verify``: the paper's Section 3.3 regression run.

Prototype curves (or ``--data FILE``) -> Sobol screening -> improved-PSO identification
-> DIR/report.json, DIR/report.md and figures: fit.png (Fig. 7a-c), convergence.png
(Fig. 7d), residuals.png (Fig. 7e), sensitivity.png (Fig. 5), curves.csv/json (the data).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from .cli_common import add_out

__all__ = ["configure", "run", "add_calibration_options", "add_identification_options", "add_model_options",
           "MODEL_DEFAULTS", "EXAMPLES", "DEFAULT_CONFIG", "CALIBRATION_DEFAULTS"]

EXAMPLES = (
    "flexcal verify --scenario table1 --out runs/table1          # paper Sec. 3.3, ~1-2 min with a warm FEM cache",
    "flexcal verify --data curves.csv --remove-offset --out runs/measured",
    "flexcal verify --scenario table1 --particles 60 --iterations 40 --sobol-n 128 --out runs/quick",
    "flexcal verify --print-config > verify.toml; flexcal verify --config verify.toml --scenario table1 --out runs/t1",
    "flexcal report runs/table1                                   # -> runs/table1/report.html",
)
MODEL_DEFAULTS = {"model_stiffness": "fem", "second_order": True}
CALIBRATION_DEFAULTS = {"sobol_n": 512, "sobol_threshold": 0.01, "particles": 300, "iterations": 150,
                        "polish": True, "remove_offset": False, "calibration_seed": 0, **MODEL_DEFAULTS}
DEFAULT_CONFIG = {"provider": "fem", **CALIBRATION_DEFAULTS}


def configure(parser: argparse.ArgumentParser) -> None:
    from .cmd_sensitivity import add_source_options

    add_source_options(parser)
    add_calibration_options(parser)
    add_out(parser, what="report.json, report.md, fit/convergence/residuals/sensitivity PNGs, curves.csv")


def add_model_options(parser: argparse.ArgumentParser) -> None:
    """Which model the calibration uses (``verify``, ``sensitivity``, ``identify``,
    ``compensate``); defaults from the command's DEFAULT_CONFIG (``MODEL_DEFAULTS``)."""
    parser.add_argument("--second-order", action=argparse.BooleanOptionalAction,
                        help="the model's second-order geometric terms: chain-force P-delta and rigid second-order "
                             "frame kinematics (docs/model.md 8; default: on; --no-second-order = the paper's model)")
    parser.add_argument("--model-stiffness", choices=("fem", "closed-form"),
                        help="the model's chain compliance: closed-form (the paper's Eq. 1) or corrected by the FEM "
                             "at the nominal design (docs/model.md 7; default %(default)s)")


def add_identification_options(parser: argparse.ArgumentParser) -> None:
    """PSO size, polish and offset removal (``verify``, ``identify``); defaults from DEFAULT_CONFIG."""
    parser.add_argument("--particles", type=int, help="PSO particles (paper: 300; default %(default)s)")
    parser.add_argument("--iterations", type=int, help="PSO iterations (paper: 150; default %(default)s)")
    parser.add_argument("--polish", action=argparse.BooleanOptionalAction,
                        help="least-squares polish of the swarm's best points (default: on)")
    parser.add_argument("--remove-offset", action=argparse.BooleanOptionalAction,
                        help="remove each leg's return offset first (paper Sec. 4.2; default: off)")


def add_calibration_options(parser: argparse.ArgumentParser) -> None:
    """The screening and identification settings (``verify``, ``sensitivity``, ``identify``);
    their defaults come from the command's DEFAULT_CONFIG."""
    parser.add_argument("--sobol-n", type=int, metavar="N", help="Sobol base sample N (power of two; default %(default)s)")
    parser.add_argument("--sobol-threshold", type=float, metavar="S",
                        help="identify sources whose total Sobol index reaches this on any output "
                             "(default %(default)s; 0 identifies all 45)")
    add_identification_options(parser)
    parser.add_argument("--calibration-seed", type=int, metavar="N",
                        help="seed of the Sobol sample and the PSO (default %(default)s)")
    add_model_options(parser)


def _plots(result, measurement, directory) -> None:
    from flexcal.calibration.plots import plot_convergence, plot_sensitivity

    from .plots import _pyplot, plot_misalignment_curves

    mis = measurement.angles - result.ideal_angles
    fitted = result.fitted_angles - result.ideal_angles
    plot_misalignment_curves(directory / "fit.png", mis, result.point_class, leg=measurement.leg, fitted=fitted,
                             title="misalignment (measured − ideal), calibrated model's fit and its point classes (Fig. 7a-c, 12)")
    plot_convergence(result.pso, directory / "convergence.png", ylabel="Eq. 13 fitness [rad]")
    plot_sensitivity(result.sobol, directory / "sensitivity.png")
    plt = _pyplot()
    residual = (result.fitted_angles - result.problem.angles) * 1e6
    fig, ax = plt.subplots(figsize=(8, 3.5))
    index = np.arange(1, residual.shape[0] + 1)
    for k, label in enumerate(("θx", "θy", "θz")):
        ax.plot(index, residual[:, k], marker="o", ms=3, lw=0.8, label=f"error {label}")
    ax.plot(index, np.linalg.norm(residual, axis=1), color="k", lw=1, label="‖Δθ‖₂")
    ax.set_xlabel("data point")
    ax.set_ylabel("orientation error [µrad]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=4)
    fig.tight_layout()
    fig.savefig(directory / "residuals.png", dpi=120)
    plt.close(fig)


def _markdown(report) -> str:
    lines = ["# Section 3.3 regression run", "",
             f"Fit: Eq. 13 fitness {report['fitness_eq13_urad']:.4g} urad, RMS {report['fit_rms_urad']:.4g} urad, "
             f"max ||Δθ|| {report['fit_max_urad']:.4g} urad; {report['n_evaluations']} model evaluations "
             f"({report['n_model_postures']} postures), {report['wall_s']:.1f} s.", "",
             f"Identified {len(report['selected'])} of 45 sources (Sobol total index >= threshold, plus the "
             f"Table 1 drive sources). Identifiability: rank {report['identifiability']['rank']} of "
             f"{report['identifiability']['n_parameters']}, condition number "
             f"{report['identifiability']['condition_number']:.3g}.", ""]
    if report["identifiability"]["groups"]:
        lines += ["Groups the trajectory cannot tell apart: " +
                  "; ".join(", ".join(g) for g in report["identifiability"]["groups"]), ""]
    if "paper_comparison" in report:
        lines += ["## Against the paper's Table 1", "",
                  "| figure | paper | ours (all identified) | beats paper | ours (identifiable only) | beats paper "
                  "| not identifiable from this trajectory |", "|---|---:|---:|---|---:|---|---|"]
        for row in report["paper_comparison"]:
            ours = "n/a (none identified)" if row["ours"] is None else f"{row['ours']:.4g}"
            meaningful = "n/a (none identifiable)" if row["ours_identifiable"] is None else \
                f"{row['ours_identifiable']:.4g}"
            lines.append(f"| {row['figure']} | {row['paper']:g} | {ours} | {'yes' if row['beats_paper'] else 'NO'} | "
                         f"{meaningful} | {'yes' if row['beats_paper_identifiable'] else 'NO'} | "
                         f"{', '.join(row['not_identifiable']) or '-'} |")
        lines += ["", f"Model chain stiffness: {report.get('model_stiffness', 'closed-form')}; second-order "
                  f"geometric terms: {'on' if report.get('model_second_order') else 'off (the paper model)'}.", ""]
    has_preset = "preset" in report["parameters"][0]
    header = "| parameter | unit | " + ("preset | " if has_preset else "") + "identified | " + \
        ("abs error | rel error | " if has_preset else "") + "identified? | identifiable? |"
    lines += ["## Parameters", "", header, "|---|---|" + "---:|" * (4 if has_preset else 1) + "---|---|"]
    for r in report["parameters"]:
        cells = [f"`{r['name']}`", r["unit"]]
        if has_preset:
            cells.append(f"{r['preset']:.5g}")
        cells.append(f"{r['identified']:.5g}")
        if has_preset:
            rel = "—" if r["rel_error"] is None else f"{100 * r['rel_error']:.2f} %"
            cells += [f"{r['abs_error']:.3g}", rel]
        cells += ["yes" if r["was_identified"] else "no (screened out, nominal)",
                  "yes" if r["identifiable"] else "no"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def run(args: argparse.Namespace) -> int:
    from flexcal.calibration.pso_settings import PSOSettings
    from flexcal.model.parameters import parameter_space

    from .cmd_sensitivity import check_sobol_options, load_source
    from .measurements import write_measurement
    from .output import staged_output, write_json
    from .model_correction import model_space
    from .verify import VerifySettings, run_verify

    if args.particles < 2 or args.iterations < 1:
        raise ValueError(f"--particles={args.particles} must be >= 2 and --iterations={args.iterations} >= 1")
    check_sobol_options(args)
    settings = VerifySettings(sobol_n=args.sobol_n, sobol_threshold=args.sobol_threshold, seed=args.calibration_seed,
                              polish=args.polish, remove_offset=args.remove_offset,
                              noise_urad=args.noise_urad if args.noise_urad else None,
                              pso=dataclasses.replace(PSOSettings(), n_particles=args.particles,
                                                      max_iterations=args.iterations))
    space = parameter_space()
    measurement, presets = load_source(args, space, progress=not args.quiet)
    space = model_space(args.model_stiffness, args.second_order, progress=not args.quiet)
    result = run_verify(measurement, space, settings, presets=presets, progress=not args.quiet)
    result.report["model_stiffness"] = ("closed-form chains scaled by FEM factors at the nominal design "
                                        "(docs/model.md 7)" if space.compliance_factors else "closed-form (paper Eq. 1)")
    result.report["model_second_order"] = bool(space.second_order)
    with staged_output(args.out, replace=args.force) as staging:
        write_json(staging / "report.json", result.report)
        (staging / "report.md").write_text(_markdown(result.report))
        write_measurement(staging / "curves.csv", measurement)
        _plots(result, measurement, staging)
    report = result.report
    print(f"flexcal verify: fit RMS {report['fit_rms_urad']:.3g} urad, max {report['fit_max_urad']:.3g} urad, "
          f"{report['n_evaluations']} evaluations, {report['wall_s']:.1f} s; wrote {args.out}/report.json, report.md")
    for row in report.get("paper_comparison", []):
        print(f"  {row['figure']}: paper {row['paper']:g}, ours {row['ours'] if row['ours'] is None else round(row['ours'], 4)} "
              f"({'beats' if row['beats_paper'] else 'misses'})")
    return 0
