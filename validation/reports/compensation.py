"""The compensation run's report: paper Tables 2-3 layout, per-point states, figures 12, 14, 15.

Definitions (errors are |measured - target| of the relative angles, per angle, [urad]):

- stages: ``uncalibrated`` = inputs of the small-deflection model (the paper's
  "Small-deflection model (before calibration)"), ``first_round`` = inputs of the
  calibrated model's inverse ("After calibration"), ``iterated`` = the last round of the
  closed loop ("Iterative approximation");
- the Mean block's proportion row = first-round reduction of the mean error,
  100 (1 - mean_first / mean_uncalibrated) (the paper's text reads its 65.4 / 79.8 / 74.8 %
  as "first-round ... average error reductions");
- the Max block's proportion row = final reduction of the max error,
  100 (1 - max_iterated / max_uncalibrated).
The paper's own proportion rows cannot be recomputed from its table with any of these
(S1 theta_x: (10.36 - 6.34) / 10.36 = 38.8 %, the table says 65.4 %); they are shown beside
ours as printed.

Classes S1/S2/S3 are the calibrated model's at each target's final inputs (the paper
classifies with the error model); the prototype's own class is listed per point.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .form_floor import form_floor_markdown
from .plots import CLASS_COLOURS, _pyplot

__all__ = ["build_report", "report_markdown", "plot_fit", "plot_first_round", "plot_iterated", "PAPER_TABLE2",
           "PAPER_TABLE3", "PAPER_GOAL", "ANGLES", "CLASSES"]

ANGLES = ("theta_x", "theta_y", "theta_z")
CLASSES = ("S1", "S2", "S3")
STAGES = ("uncalibrated", "first_round", "iterated")
STAGE_LABELS = {"uncalibrated": "Small-deflection model (before calibration)", "first_round": "After calibration",
                "iterated": "Iterative approximation"}


def _by_class(rows: tuple) -> dict[str, list[float]]:
    return {c: list(r) for c, r in zip(CLASSES, rows)}


# Paper Table 3 (urad; proportions in %), per class the (theta_x, theta_y, theta_z) triple
PAPER_TABLE3 = {
    "mean": {"uncalibrated": _by_class(((10.36, 129.29, 68.83), (17.80, 201.70, 96.45), (11.51, 562.33, 53.73))),
             "first_round": _by_class(((6.34, 22.98, 18.40), (7.60, 26.09, 12.87), (5.90, 119.94, 9.89))),
             "iterated": _by_class(((4.22, 6.61, 1.40), (2.43, 7.40, 2.52), (3.57, 8.36, 3.03))),
             "proportion_pct": _by_class(((65.4, 86.7, 74.8), (66.4, 90.4, 88.9), (70.6, 79.8, 86.4)))},
    "max": {"uncalibrated": _by_class(((20.12, 182.15, 86.75), (36.92, 576.19, 212.22), (32.92, 674.49, 199.37))),
            "first_round": _by_class(((16.82, 41.23, 23.06), (25.01, 99.34, 29.73), (16.38, 157.74, 22.59))),
            "iterated": _by_class(((14.59, 21.54, 3.78), (6.08, 21.39, 6.75), (9.37, 21.66, 6.74))),
            "proportion_pct": _by_class(((59.7, 87.7, 76.7), (38.6, 85.9, 88.8), (70.2, 79.1, 91.7)))},
}
# Paper Table 2: calibration fit after removing the systematic deviation (urad)
PAPER_TABLE2 = {"mean": _by_class(((1.22, 0.81, 1.31), (1.45, 1.54, 0.97), (1.20, 0.90, 1.55))),
                "max": _by_class(((2.70, 2.00, 3.50), (3.45, 4.11, 4.38), (1.56, 3.08, 4.29)))}
# The goal: paper Sec. 4.3 text (first-round mean reductions, final max errors)
PAPER_GOAL = {"first_round_mean_reduction_pct": (65.4, 79.8, 74.8), "final_max_error_urad": (14.5, 21.5, 6.7)}


def _per_angle(values) -> dict[str, float | None]:
    return {a: (None if v is None or not np.isfinite(v) else float(v)) for a, v in zip(ANGLES, values)}


def _stats(errors_urad: np.ndarray, classes: np.ndarray) -> dict[str, Any]:
    """{"all"|S1|S2|S3: {"n", "mean": per angle, "max": per angle}} of |errors| (n, 3) [urad]."""
    out = {}
    for name in ("all",) + CLASSES:
        mask = np.ones(len(classes), bool) if name == "all" else classes == name
        e = np.abs(errors_urad[mask])
        out[name] = {"n": int(mask.sum()),
                     "mean": _per_angle(e.mean(axis=0) if mask.any() else [None] * 3),
                     "max": _per_angle(e.max(axis=0) if mask.any() else [None] * 3)}
    return out


def _reduction(before: dict, after: dict) -> dict[str, float | None]:
    return {a: (None if before[a] in (None, 0.0) or after[a] is None else 100.0 * (1.0 - after[a] / before[a]))
            for a in ANGLES}


def _table2(result) -> dict[str, Any]:
    residual = (result.verify.fitted_angles - result.verify.problem.angles) * 1e6
    return _stats(residual, np.asarray(result.verify.point_class))


def _points(result) -> list[dict[str, Any]]:
    rows = []
    for k, target in enumerate(result.targets):
        row = {"point": k + 1, "target_urad": target * 1e6, "model_class": str(result.model_class[k]),
               "release_um": result.release[k] * 1e6, "first_inputs_mm": result.first_inputs[k] * 1e3}
        if result.loop is not None:
            row.update({
                "final_inputs_mm": result.loop.final.inputs[k] * 1e3,
                "prototype_class": str(result.records[-1].point_class[k]),
                "nut_offsets_um": result.records[-1].nut_offsets[k] * 1e6,
                "error_uncalibrated_urad": (result.uncalibrated.measured[k] - target) * 1e6,
                "error_first_round_urad": result.loop.first.error[k] * 1e6,
                "error_iterated_urad": result.loop.final.error[k] * 1e6,
                "true_error_iterated_urad": (result.records[-1].true[k] - target) * 1e6,
            })
        rows.append(row)
    return rows


def build_report(result) -> dict[str, Any]:
    """report.json content of a ``CompensationResult`` (``flexcal.validation.runs.compensate``)."""
    verify = result.verify.report
    report: dict[str, Any] = {
        "n_targets": int(len(result.targets)),
        # the estimation's record (--method map/free): the error bars' sources, the model-error budget, the profile bars
        "identification": {**{k: verify[k] for k in ("fit_rms_urad", "fit_max_urad", "fitness_eq13_urad", "selected",
                                                     "n_evaluations", "offset_removed")},
                           "estimation": verify.get("estimation")},
        "identified_parameters": [{k: r[k] for k in ("name", "unit", "identified", "std_error")
                                   + (("preset",) if "preset" in r else ())}
                                  for r in verify["parameters"] if r["was_identified"]],
        "return_offsets_urad": [{"leg": leg, **_per_angle(offset * 1e6)} for leg, offset in
                                result.return_offsets.items()],
        "table2": _table2(result),
        "model_form_floor": verify["model_form_floor"],
        "table2_paper": PAPER_TABLE2,
        "points": _points(result),
        "bench": result.bench,
        "definitions": __doc__.split("Definitions", 1)[1].strip(),
    }
    if result.loop is None:
        report["summary"] = {"n_targets": report["n_targets"], "driven": False,
                             "note": "real measurements: stopped after step 3; send first_inputs_mm"}
        return report
    classes = np.asarray(result.model_class)
    errors = {"uncalibrated": (result.uncalibrated.measured - result.targets) * 1e6,
              "first_round": result.loop.first.error * 1e6, "iterated": result.loop.final.error * 1e6}
    table3 = {stage: _stats(e, classes) for stage, e in errors.items()}
    for group in ("all",) + CLASSES:
        table3.setdefault("proportion_pct", {})[group] = {
            "mean": _reduction(table3["uncalibrated"][group]["mean"], table3["first_round"][group]["mean"]),
            "max": _reduction(table3["uncalibrated"][group]["max"], table3["iterated"][group]["max"])}
    first_reduction = table3["proportion_pct"]["all"]["mean"]
    final_max = table3["iterated"]["all"]["max"]
    true_final = np.abs(result.records[-1].true - result.targets).max(axis=0) * 1e6
    goal = []
    for figure, ours, better in (("first_round_mean_reduction_pct", first_reduction, "higher"),
                                 ("final_max_error_urad", final_max, "lower")):
        for angle, paper in zip(ANGLES, PAPER_GOAL[figure]):
            met = ours[angle] >= paper if better == "higher" else ours[angle] < paper
            goal.append({"figure": figure, "angle": angle, "paper": paper, "ours": ours[angle], "met": bool(met)})
    report.update({
        "first_round_mean_reduction_pct": first_reduction,
        "final_max_error_urad": final_max,
        "final_max_true_error_urad": _per_angle(true_final),
        "goal": goal,
        "goal_met": all(g["met"] for g in goal),
        "converged": bool(result.loop.converged),
        "n_corrections": result.loop.n_corrections,
        "tolerance_urad": result.loop.settings.tolerance * 1e6,
        "rounds": [{"round": k, "n_corrected": int(r.corrected.sum()),
                    "mean_error_urad": _per_angle(np.abs(r.error).mean(axis=0) * 1e6),
                    "max_error_urad": _per_angle(r.max_abs_error * 1e6)} for k, r in enumerate(result.loop.rounds)],
        "table3": table3,
        "table3_paper": PAPER_TABLE3,
    })
    report["summary"] = {"n_targets": report["n_targets"], "converged": report["converged"],
                         "n_corrections": report["n_corrections"], "goal_met": report["goal_met"],
                         **{f"first_round_mean_reduction_pct_{a}": first_reduction[a] for a in ANGLES},
                         **{f"final_max_error_urad_{a}": final_max[a] for a in ANGLES}}
    return report


def _cell(value, digits: int = 2) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def _table3_markdown(report: dict[str, Any]) -> list[str]:
    table, paper = report["table3"], report["table3_paper"]
    header = "| | state | " + " | ".join(f"{c} θ{a[-1]}" for c in CLASSES for a in ANGLES) + " |"
    lines = [header, "|---|---|" + "---:|" * 9]
    for block in ("mean", "max"):
        for stage in STAGES + ("proportion_pct",):
            ours = table[stage] if stage != "proportion_pct" else None
            cells = []
            for c in CLASSES:
                for a in ANGLES:
                    value = ours[c][block][a] if ours else table["proportion_pct"][c][block][a]
                    unit = " %" if stage == "proportion_pct" else ""
                    cells.append(f"{_cell(value, 1 if unit else 2)}{unit} ({paper[block][stage][c][ANGLES.index(a)]:g})")
            label = STAGE_LABELS.get(stage, "first-round reduction of the mean" if block == "mean"
                                     else "final reduction of the max")
            lines.append(f"| {block} | {label} | " + " | ".join(cells) + " |")
    counts = ", ".join(f"{c}: {table['uncalibrated'][c]['n']}" for c in CLASSES)
    return lines + ["", f"Ours (paper's in brackets), urad unless %; targets per class (calibrated model): {counts}."]


def report_markdown(report: dict[str, Any]) -> str:
    """report.md: goal, Table 3 layout, Table 2, rounds, per-point states."""
    ident = report["identification"]
    lines = ["# Closed-loop compensation (paper Sec. 4, Fig. 9)", "",
             f"Identification on the offset-removed curve: fit RMS {ident['fit_rms_urad']:.3g} urad, max "
             f"{ident['fit_max_urad']:.3g} urad, {len(ident['selected'])} sources identified. Return offsets "
             "removed first (Sec. 4.2, urad): " + ("; ".join(f"leg {o['leg']}: " + ", ".join(_cell(o[a]) for a in ANGLES)
                                                   for o in report["return_offsets_urad"]) or "none"), ""]
    discrepancy = (ident.get("estimation") or {}).get("discrepancy")
    if discrepancy:  # --method map/free: what the identified values' standard errors carry
        lines += [f"Error bars of the identified values (report.json `identified_parameters`, `std_error`): "
                  f"{discrepancy['error_bars']}.", ""]
    if "goal" in report:
        lines += [f"{report['n_targets']} targets, {report['n_corrections']} corrective round(s), converged to "
                  f"{report['tolerance_urad']:g} urad: {'yes' if report['converged'] else 'NO'}.", "",
                  "## Against the paper (Sec. 4.3)", "", "| figure | angle | paper | ours | met |", "|---|---|---:|---:|---|"]
        lines += [f"| {g['figure']} | {g['angle']} | {g['paper']:g} | {g['ours']:.2f} | {'yes' if g['met'] else 'NO'} |"
                  for g in report["goal"]]
        true = report["final_max_true_error_urad"]
        lines += ["", "Final max error of the frame's true rotation (what the sensor cannot see): "
                  + ", ".join(f"{a} {true[a]:.2f}" for a in ANGLES) + " urad.", "",
                  "## Table 3 layout: errors before and after calibration", ""] + _table3_markdown(report)
        lines += ["", "## Rounds", "", "| round | points corrected | mean θx, θy, θz [urad] | max θx, θy, θz [urad] |",
                  "|---:|---:|---|---|"]
        lines += [f"| {r['round']} | {r['n_corrected']} | " + ", ".join(_cell(r['mean_error_urad'][a]) for a in ANGLES)
                  + " | " + ", ".join(_cell(r['max_error_urad'][a]) for a in ANGLES) + " |" for r in report["rounds"]]
    lines += [""] + form_floor_markdown(report.get("model_form_floor"))
    t2, p2 = report["table2"], report["table2_paper"]
    lines += ["", "## Table 2 layout: calibration fit by class (offsets removed)", "",
              "| | " + " | ".join(f"{c} θ{a[-1]}" for c in CLASSES for a in ANGLES) + " |", "|---|" + "---:|" * 9]
    for block in ("mean", "max"):
        lines.append(f"| {block} | " + " | ".join(f"{_cell(t2[c][block][a])} ({p2[block][c][ANGLES.index(a)]:g})"
                                                   for c in CLASSES for a in ANGLES) + " |")
    lines += ["", "## Points", "", "| # | target θx, θy, θz [urad] | model class | prototype class | "
              "fx_A D1, D2, D3 [um] | final error θx, θy, θz [urad] |", "|---:|---|---|---|---|---|"]
    for p in report["points"]:
        final = p.get("error_iterated_urad")
        lines.append(f"| {p['point']} | " + ", ".join(f"{v:.0f}" for v in p["target_urad"]) + f" | {p['model_class']} | "
                     f"{p.get('prototype_class', '—')} | " + ", ".join(f"{v:.2f}" for v in p["release_um"]) + " | "
                     + ("—" if final is None else ", ".join(f"{v:.2f}" for v in final)) + " |")
    return "\n".join(lines + ["", "Definitions: " + " ".join(report["definitions"].split())]) + "\n"


# --- figures ---------------------------------------------------------------------------------

def plot_fit(path, misalignment: np.ndarray, fitted: np.ndarray, release: np.ndarray, classes, leg) -> None:
    """Fig. 12: offset-removed misalignment (n, 3) [rad] and the calibrated fit, classes
    coloured; bottom panel each driving chain's distance from its clearance zero (n, 3) [m]."""
    plt = _pyplot()
    n = misalignment.shape[0]
    index = np.arange(1, n + 1)
    classes = np.asarray(classes)
    fig, axes = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    for k, ax in enumerate(axes[:3]):
        ax.plot(index, misalignment[:, k] * 1e6, color="0.6", lw=1)
        for name, colour in CLASS_COLOURS.items():
            mask = classes == name
            if mask.any():
                ax.scatter(index[mask], misalignment[mask, k] * 1e6, s=16, color=colour, label=f"fitting {name}")
        ax.plot(index, fitted[:, k] * 1e6, color="k", ls="--", lw=1, label="calibrated model")
        ax.set_ylabel(f"{('θx', 'θy', 'θz')[k]} misalignment [µrad]")
        ax.grid(alpha=0.3)
    for j in range(3):
        axes[3].plot(index, release[:, j] * 1e6, lw=1, marker=".", label=f"D{j + 1}")
    axes[3].axhline(0.0, color="k", lw=0.8)
    axes[3].set_ylabel("fx_A: distance from\nclearance zero [µm]")
    axes[3].set_xlabel("sampling point")
    for ax in axes:
        for boundary in np.flatnonzero(np.diff(np.asarray(leg)) != 0):
            ax.axvline(boundary + 1.5, color="0.8", ls=":", lw=1)
    axes[0].legend(fontsize=8, ncol=4)
    axes[3].legend(fontsize=8, ncol=3)
    fig.suptitle("calibration fit on the offset-removed curve and chain states (cf. paper Fig. 12)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _sorted_axes(report):
    points = report["points"]
    order = np.argsort([np.linalg.norm(p["target_urad"]) for p in points], kind="stable")
    classes = np.array([points[k]["model_class"] for k in order])
    return points, order, classes


def plot_first_round(path, report: dict[str, Any]) -> None:
    """Fig. 14: |error| before (small-deflection model) and after the first calibrated
    round per angle, points sorted by total adjustment magnitude."""
    plt = _pyplot()
    points, order, classes = _sorted_axes(report)
    x = np.arange(1, len(order) + 1)
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for k, ax in enumerate(axes):
        before = np.abs([points[i]["error_uncalibrated_urad"][k] for i in order])
        after = np.abs([points[i]["error_first_round_urad"][k] for i in order])
        ax.plot(x, before, color="0.5", marker="s", ms=4, lw=0.8, label="small-deflection model")
        ax.plot(x, after, color="k", lw=0.8)
        for name, colour in CLASS_COLOURS.items():
            mask = classes == name
            if mask.any():
                ax.scatter(x[mask], after[mask], color=colour, s=22, zorder=3, label=f"calibrated, {name}")
        red = report["table3"]["proportion_pct"]["all"]["mean"][ANGLES[k]]
        ax.set_title(f"{('θx', 'θy', 'θz')[k]}: mean error reduced by {red:.1f} %", fontsize=9)
        ax.set_ylabel("|error| [µrad]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncol=4)
    axes[-1].set_xlabel("validation point (ascending total adjustment magnitude)")
    fig.suptitle("first-round compensation with the calibrated model (cf. paper Fig. 14)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_iterated(path, report: dict[str, Any]) -> None:
    """Fig. 15: signed error after the iterative approximation per angle (sorted as Fig. 14)
    with the tolerance band, and the max |error| per round."""
    plt = _pyplot()
    points, order, classes = _sorted_axes(report)
    x = np.arange(1, len(order) + 1)
    tol = report["tolerance_urad"]
    fig, axes = plt.subplots(4, 1, figsize=(9, 10))
    for k, ax in enumerate(axes[:3]):
        final = np.array([points[i]["error_iterated_urad"][k] for i in order])
        ax.axhspan(-tol, tol, color="0.9", label=f"tolerance ±{tol:g} µrad")
        ax.plot(x, final, color="k", lw=0.8)
        for name, colour in CLASS_COLOURS.items():
            mask = classes == name
            if mask.any():
                ax.scatter(x[mask], final[mask], color=colour, s=22, zorder=3, label=name)
        ax.set_ylabel(f"{('θx', 'θy', 'θz')[k]} error [µrad]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncol=4)
    axes[2].set_xlabel("validation point (ascending total adjustment magnitude)")
    rounds = report["rounds"]
    for k, angle in enumerate(ANGLES):
        axes[3].semilogy([r["round"] for r in rounds], [max(r["max_error_urad"][angle], 1e-3) for r in rounds],
                         marker="o", label=("θx", "θy", "θz")[k])
    axes[3].axhline(tol, color="k", ls=":", lw=1)
    axes[3].set_xticks([r["round"] for r in rounds])
    axes[3].set_xlabel("round (0 = calibrated model's inverse)")
    axes[3].set_ylabel("max |error| [µrad]")
    axes[3].grid(alpha=0.3)
    axes[3].legend(fontsize=8)
    fig.suptitle("after the closed-loop iterative approximation (cf. paper Fig. 15)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
