"""``flexcal verify``: the paper's Section 3.3 regression run.

Prototype curves (or ``--data FILE``) -> Sobol screening -> improved-PSO identification
-> DIR/report.json, DIR/report.md and figures: fit.png (Fig. 7a-c), convergence.png
(Fig. 7d), residuals.png (Fig. 7e), sensitivity.png (Fig. 5), curves.csv/json (the data).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--scenario", help="make the data with the virtual prototype: table1, nominal or a TOML file")
    source.add_argument("--data", help="a measurement CSV (synthetic or real); its JSON sidecar's presets, if any, "
                                       "give the error columns")
    parser.add_argument("--seed", type=int, default=None, help="scenario seed (drawn errors, noise)")
    parser.add_argument("--noise-urad", type=float, default=None, help="sensor noise of the scenario [urad]")
    parser.add_argument("--provider", choices=("fem", "analytic"), default="fem",
                        help="prototype segment stiffness (default fem; analytic only for quick checks)")
    parser.add_argument("--sobol-n", type=int, default=512, help="Sobol base sample N (power of two; default 512)")
    parser.add_argument("--sobol-threshold", type=float, default=0.01,
                        help="identify sources whose total Sobol index reaches this on any output (default 0.01; "
                             "0 identifies all 45)")
    parser.add_argument("--particles", type=int, default=300, help="PSO particles (paper: 300)")
    parser.add_argument("--iterations", type=int, default=150, help="PSO iterations (paper: 150)")
    parser.add_argument("--no-polish", action="store_true", help="skip the least-squares polish")
    parser.add_argument("--remove-offset", action="store_true", help="remove return offsets first (paper Sec. 4.2)")
    parser.add_argument("--calibration-seed", type=int, default=0, help="seed of the Sobol sample and the PSO")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--quiet", action="store_true")


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
        lines += ["## Against the paper's Table 1", "", "| figure | paper | ours | beats paper |", "|---|---:|---:|---|"]
        for row in report["paper_comparison"]:
            ours = "n/a (none identified)" if row["ours"] is None else f"{row['ours']:.4g}"
            lines.append(f"| {row['figure']} | {row['paper']:g} | {ours} | "
                         f"{'yes' if row['beats_paper'] else 'NO'} |")
        lines.append("")
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

    from .measurements import read_measurement, write_measurement
    from .output import staged_output, write_json
    from .verify import VerifySettings, run_verify

    if args.particles < 2 or args.iterations < 1:
        raise ValueError("--particles must be >= 2 and --iterations >= 1")
    if args.sobol_n < 2 or args.sobol_n & (args.sobol_n - 1):
        raise ValueError(f"--sobol-n={args.sobol_n} must be a power of two (e.g. 512)")
    space = parameter_space()
    presets = None
    if args.scenario is not None:
        from .cmd_truth import stiffness_provider
        from .scenario import load_scenario
        from .truth import make_truth

        scenario = load_scenario(args.scenario, seed=args.seed, noise_urad=args.noise_urad)
        measurement = make_truth(scenario, stiffness_provider(args.provider, progress=not args.quiet),
                                 progress=not args.quiet).measurement
        presets = scenario.values
    else:
        measurement = read_measurement(args.data)
        found = measurement.metadata.get("preset_errors")
        if found:
            presets = space.build_values({e["name"]: e["value"] for e in found}, display_units=True)
    if not 0.0 <= args.sobol_threshold <= 1.0:
        raise ValueError(f"--sobol-threshold={args.sobol_threshold} must be in [0, 1]")
    settings = VerifySettings(sobol_n=args.sobol_n, sobol_threshold=args.sobol_threshold, seed=args.calibration_seed, polish=not args.no_polish,
                              remove_offset=args.remove_offset,
                              noise_urad=args.noise_urad if args.noise_urad else None,
                              pso=dataclasses.replace(PSOSettings(), n_particles=args.particles,
                                                      max_iterations=args.iterations))
    result = run_verify(measurement, space, settings, presets=presets, progress=not args.quiet)
    with staged_output(args.out) as staging:
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
