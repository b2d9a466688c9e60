"""``flexcal identify``'s report.md and figures (fit.png, convergence.png), from its
report and the run's result (rendering only; the identification is ``runs.verify``)."""

from __future__ import annotations

from .form_floor import form_floor_markdown

__all__ = ["identify_markdown", "write_identify_figures"]

_HOW = {"paper": "improved PSO + polish", "map": "MAP with the paper's ranges as prior", "free": "free least squares"}


def identify_markdown(report: dict, *, has_pso: bool, has_preset: bool) -> str:
    """report.md of ``flexcal identify`` from its report.json data; has_pso: the run has a
    convergence.png; has_preset: the data are synthetic (preset and error columns)."""
    summary, ident, rows = report["summary"], report["identifiability"], report["parameters"]
    lines = [f"# Identification ({_HOW[summary['method']]})", "",
             f"{summary['n_identified']} sources identified from {summary['n_points']} postures; fit RMS "
             f"{summary['fit_rms_urad']:.4g} urad, "
             f"max ||Δθ|| {summary['fit_max_urad']:.4g} urad; identifiability rank {ident['rank']} of "
             f"{ident['n_parameters']}" + (f", condition number {ident['condition_number']:.3g}."
                                           if "condition_number" in ident else "."), "",
             "![fit](fit.png)", ""] + (["![convergence](convergence.png)", ""] if has_pso else []) + [
             "## Identified sources", "",
             "| parameter | unit | identified | std error | " + ("preset | abs error | " if has_preset else "")
             + "identifiable |",
             "|---|---|---:|---:|" + ("---:|---:|" if has_preset else "") + "---|"]
    for r in (r for r in rows if r["was_identified"]):
        cells = [f"`{r['name']}`", r["unit"], f"{r['identified']:.5g}",
                 "–" if r["std_error"] is None else f"{r['std_error']:.3g}"]
        if has_preset:
            cells += [f"{r['preset']:.5g}", f"{r['abs_error']:.3g}"]
        lines.append("| " + " | ".join(cells + ["yes" if r["identifiable"] else "no"]) + " |")
    lines += [""] + form_floor_markdown(report["model_form_floor"])
    return "\n".join(lines) + "\n"


def write_identify_figures(directory, result, measurement, space) -> None:
    """fit.png (misalignment, measured and fitted, against the ideal model) and, for a PSO
    run, convergence.png of a ``runs.verify.VerifyResult`` in ``directory``."""
    from flexcal.calibration.plots import plot_convergence
    from flexcal.model.forward import ideal_angles

    from .plots import plot_misalignment_curves

    ideal = ideal_angles(measurement.inputs, space)
    classes = measurement.metadata.get("prototype", {}).get("point_class") or ["S3"] * measurement.n_points
    plot_misalignment_curves(directory / "fit.png", result.problem.angles - ideal, classes, leg=measurement.leg,
                             fitted=result.fitted_angles - ideal,
                             title="misalignment (measured − ideal) and the identified model")
    if result.pso is not None:
        plot_convergence(result.pso, directory / "convergence.png", ylabel="Eq. 13 fitness [rad]")
