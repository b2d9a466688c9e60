"""The report of ``flexcal verify`` (paper Sec. 3.3 regression run): report.md
(``verify_markdown``), its figures (``write_verify_figures``: fit.png Fig. 7a-c, residuals.png
Fig. 7e, convergence.png Fig. 7d, sensitivity.png Fig. 5, calibration.png) and the terminal
summary (``verify_lines``), all from the run's result and report.json data."""

from __future__ import annotations

import numpy as np

from .form_floor import form_floor_line, form_floor_markdown
from .safe_markdown import md_text

__all__ = ["verify_markdown", "identification_lines", "write_verify_figures", "plot_calibration", "verify_lines"]


def write_verify_figures(result, measurement, directory) -> None:
    """fit.png, residuals.png, and where the run has them convergence.png, sensitivity.png,
    calibration.png of a ``runs.verify.VerifyResult`` in ``directory``."""
    from flexcal.calibration.plots import plot_convergence, plot_sensitivity

    from .plots import _pyplot, plot_misalignment_curves

    mis = measurement.angles - result.ideal_angles
    fitted = result.fitted_angles - result.ideal_angles
    plot_misalignment_curves(directory / "fit.png", mis, result.point_class, leg=measurement.leg, fitted=fitted,
                             title="misalignment (measured − ideal), calibrated model's fit and its point classes (Fig. 7a-c, 12)")
    if result.pso is not None:
        plot_convergence(result.pso, directory / "convergence.png", ylabel="Eq. 13 fitness [rad]")
    if result.sobol is not None:
        plot_sensitivity(result.sobol, directory / "sensitivity.png")
    if "z_rms_identifiable" in result.report:
        plot_calibration(directory / "calibration.png", result.report["parameters"])
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


def plot_calibration(path, rows) -> None:
    """Identified error against its standard error (both in standard errors' units: |z|), one
    dot per source with an error bar; the honest band |z| <= 2 shaded (Fig.: calibration of
    the error bars)."""
    from .plots import _pyplot

    plt = _pyplot()
    shown = [r for r in rows if r.get("z_score") is not None and r["std_error"]]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for identifiable, marker, label in ((True, "o", "identifiable (base)"), (False, "x", "not identifiable")):
        part = [r for r in shown if r["identifiable"] == identifiable]
        if part:
            se = np.array([r["std_error"] for r in part]) / np.array([r["nominal"] if r["nominal"] else 1.0
                                                                      for r in part])
            err = np.array([r["abs_error"] for r in part]) / np.array([r["nominal"] if r["nominal"] else 1.0
                                                                       for r in part])
            axes[0].loglog(np.abs(se), np.abs(err) + 1e-12, marker, label=label, alpha=0.8)
            axes[1].plot([r["z_score"] for r in part], marker, label=label)
    lim = axes[0].get_xlim()
    axes[0].plot(lim, lim, "k-", lw=0.8, label="error = 1 standard error")
    axes[0].plot(lim, [2 * v for v in lim], "k--", lw=0.8, label="2 standard errors")
    axes[0].set_xlabel("predicted: standard error (relative to nominal, or absolute where nominal is 0)")
    axes[0].set_ylabel("actual: |identified − preset|")
    axes[0].legend(fontsize=7)
    axes[1].axhspan(-2, 2, color="0.9")
    axes[1].set_xlabel("source (space order within each class)")
    axes[1].set_ylabel("z = error / standard error")
    if shown:
        axes[1].legend(fontsize=7)
    fig.suptitle("calibration of the error bars: predicted vs actual error")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def identification_lines(report) -> list[str]:
    """The Markdown lines saying how the sources were identified (method, prior, base parameters)."""
    method = report.get("method", "paper")
    ident = report["identifiability"]
    if method == "paper":
        return [f"Method: the paper's (Sobol screening + improved PSO). Identified {len(report['selected'])} of 45 "
                f"sources (Sobol total index >= threshold, plus the Table 1 drive sources); the rest stay at nominal. "
                f"Identifiability: rank {ident['rank']} of {ident['n_parameters']}, condition number "
                f"{ident['condition_number']:.3g}.", ""] + (
            ["Groups the trajectory cannot tell apart: " + "; ".join(", ".join(g) for g in ident["groups"]), ""]
            if ident["groups"] else [])
    est = report["estimation"]
    cv = est["cross_validation"]
    scale = "none (free least squares)" if est["prior_scale"] is None else f"{est['prior_scale']:g}"
    lines = [f"Method: {method} — all {ident['n_parameters']} sources estimated at once; prior scale {scale}"
             + ("" if cv is None else " chosen by held-out cross-validation over whole legs (" +
                ", ".join(f"{s:g}: {r:.3g} urad" for s, r in zip(cv["scales"], cv["held_out_rms_urad"])) + ")")
             + f". Noise {est['noise_urad']:.3g} urad, {est['noise_source']}; effective parameters "
             f"{est['effective_parameters']:.1f} of {est['n_observations']} observations.", "",
             f"Base parameters (identified to <= {100 * est['base_parameters']['max_std_of_range']:g} % of their "
             f"range by the data alone): {ident['rank']} of {ident['n_parameters']}; the other sources stay near "
             f"their prior. Combinations (coefficients in range units):", ""]
    table = report.get("base_parameters", {})
    with_truth = any("z_score" in r for r in table.get("rows", []))
    lines += ["| base parameter | estimate | std error | " + ("true | z |" if with_truth else ""),
              "|---|---:|---:|" + ("---:|---:|" if with_truth else "")]
    for r in table.get("rows", []):
        z = "—" if r.get("z_score") is None else f"{r['z_score']:.2f}"
        lines.append(f"| {r['label']} | {r['estimate_unit']:.4g} | {r['std_unit']:.3g} | "
                     + (f"{r['true_unit']:.4g} | {z} |" if with_truth else ""))
    if any(".dy" in r["label"] or ".dz" in r["label"] for r in table.get("rows", [])):
        lines += ["", "`X.dy`, `X.dz`: a mount offset's Cartesian components (0.5 at zero offset), the coordinates "
                      "the estimator works in; the sources' table gives its magnitude and direction."]
    if with_truth and table.get("z_rms") is not None:
        lines += ["", f"RMS of the base parameters' z-scores: {table['z_rms']:.3g} "
                      f"(over {table.get('n_z_scores', len(table['rows']))})."]
    lines += ["", "Sources identified alone (their own values are meaningful): "
              + (", ".join(table.get("pure", [])) or "none"), ""]
    return lines


def verify_markdown(report) -> str:
    """report.md of ``flexcal verify`` from its report.json data."""
    lines = ["# Section 3.3 regression run", "",
             f"Fit: Eq. 13 fitness {report['fitness_eq13_urad']:.4g} urad, RMS {report['fit_rms_urad']:.4g} urad, "
             f"max ||Δθ|| {report['fit_max_urad']:.4g} urad over {report['n_points']} postures; "
             f"{report['n_evaluations']} model evaluations ({report['n_model_postures']} postures) "
             f"(wall-clock times: timings.json).", ""]
    if report.get("fit_rms_over_noise_floor") is not None:
        lines += [f"Fit RMS / sensor noise floor: {report['fit_rms_over_noise_floor']:.3g}.", ""]
    if report.get("z_rms_identifiable") is not None:
        lines += [f"RMS of the z-scores (error / standard error) of the {report['n_z_scores']} identifiable sources: "
                  f"{report['z_rms_identifiable']:.3g} (honest error bars: about 1).", ""]
    lines += identification_lines(report)
    lines += form_floor_markdown(report.get("model_form_floor"))
    if "paper_comparison" in report:
        lines += ["## Against the paper's Table 1", "",
                  "| figure | paper | ours (all identified) | beats paper | ours (identifiable only) | beats paper "
                  "| not identifiable from this trajectory | not observable on this mount |",
                  "|---|---:|---:|---|---:|---|---|---|"]
        for row in report["paper_comparison"]:
            hidden = "; ".join(f"{n}: {why}" for n, why in row.get("not_observable", {}).items()) or "-"
            if not row.get("shown", True):
                lines.append(f"| {row['figure']} | {row['paper']:g} | not observable on this mount | - | - | - | - | "
                             f"{hidden} |")
                continue
            ours = "n/a (none identified)" if row["ours"] is None else f"{row['ours']:.4g}"
            meaningful = "n/a (none identifiable)" if row["ours_identifiable"] is None else \
                f"{row['ours_identifiable']:.4g}"
            lines.append(f"| {row['figure']} | {row['paper']:g} | {ours} | {'yes' if row['beats_paper'] else 'NO'} | "
                         f"{meaningful} | {'yes' if row['beats_paper_identifiable'] else 'NO'} | "
                         f"{', '.join(row['not_identifiable']) or '-'} | {hidden} |")
        lines += ["", f"Model: {report['model']}." if "model" in report else
                  f"Model chain stiffness: {report.get('model_stiffness', 'closed-form')}; second-order "
                  f"geometric terms: {'on' if report.get('model_second_order') else 'off (the paper model)'}.", ""]
    has_preset = "preset" in report["parameters"][0]
    header = "| parameter | unit | " + ("preset | " if has_preset else "") + "identified | std error | " + \
        ("abs error | rel error | z | " if has_preset else "") + "identified? | identifiable? |"
    lines += ["## Parameters", "", header, "|---|---|" + "---:|" * (6 if has_preset else 2) + "---|---|"]
    for r in report["parameters"]:
        cells = [f"`{r['name']}`", r["unit"]]
        if has_preset:
            cells.append(f"{r['preset']:.5g}")
        cells.append(f"{r['identified']:.5g}")
        cells.append("—" if r.get("std_error") is None else ("open*" if "undetermined" in r else f"{r['std_error']:.3g}"))
        if has_preset:
            rel = "—" if r["rel_error"] is None else f"{100 * r['rel_error']:.2f} %"
            z = "—" if r.get("z_score") is None else f"{r['z_score']:.2f}"
            cells += [f"{r['abs_error']:.3g}", rel, z]
        cells += ["yes" if r["was_identified"] else "no (screened out, nominal)",
                  "yes" if r["identifiable"] else "no"]
        lines.append("| " + " | ".join(cells) + " |")
    lines += [f"\n\\* `{r['name']}`: {md_text(r['undetermined'])}." for r in report["parameters"] if "undetermined" in r]
    return "\n".join(lines) + "\n"


def verify_lines(report, out) -> list[str]:
    """The terminal summary of ``flexcal verify`` (``out``: the run folder's name)."""
    lines = [f"flexcal verify: fit RMS {report['fit_rms_urad']:.3g} urad, max {report['fit_max_urad']:.3g} urad, "
             f"{report['n_evaluations']} evaluations, {report['wall_s']:.1f} s; wrote {out}/report.json, report.md",
             "  " + form_floor_line(report.get("model_form_floor"))]
    if report.get("z_rms_identifiable") is not None:
        lines.append(f"  z-scores of the {report['n_z_scores']} identifiable sources: RMS {report['z_rms_identifiable']:.3g}")
    z_base = report.get("base_parameters", {}).get("z_rms")
    if z_base is not None and np.isfinite(z_base):
        table = report["base_parameters"]
        lines.append(f"  z-scores of the {table.get('n_z_scores', len(table['rows']))} base parameters: RMS "
                     f"{table['z_rms']:.3g}")
    for row in report.get("paper_comparison", []):
        if not row.get("shown", True):
            lines.append(f"  {row['figure']}: paper {row['paper']:g}, not observable on this mount")
            continue
        ours = row["ours_identifiable"] if report.get("method", "paper") != "paper" else row["ours"]
        beats = row["beats_paper_identifiable"] if report.get("method", "paper") != "paper" else row["beats_paper"]
        verdict = "none identifiable from this trajectory" if ours is None else "beats" if beats else "misses"
        lines.append(f"  {row['figure']}: paper {row['paper']:g}, ours {ours if ours is None else round(ours, 4)} "
                     f"({verdict})")
    return lines
