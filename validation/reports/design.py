"""``flexcal design``'s report.md and design.png, from its report and design (rendering only;
the design is ``calibration/design.py``)."""

from __future__ import annotations

import numpy as np

from .plots import _pyplot

__all__ = ["markdown", "plot_design"]


def markdown(report: dict) -> str:
    """report.md of ``flexcal design``."""
    d, s = report["designed"], report["standard_trajectory"]
    cond = lambda v: "inf (rank-deficient)" if v is None else f"{v:.3g}"  # noqa: E731
    lines = ["# Designed calibration trajectory", "",
             f"{report['n_points']} postures chosen from {report['n_candidates']} candidates, noise "
             f"{report['noise_urad']:g} urad, prior scale {report['prior_scale']:g}, model inadequacy: "
             f"{report['inadequacy']} (wall-clock time: timings.json).", "",
             f"Criterion: {report['criterion']}.", "",
             "| figure | designed | standard trajectory (77) |", "|---|---:|---:|",
             *_drives_lines(report.get("drives_criterion")),
             f"| log det M (D-criterion) | {d['log_det_information']:.2f} | {s['log_det_information']:.2f} |",
             f"| det(M)^(1/45) | {d['d_efficiency']:.4g} | {s['d_efficiency']:.4g} |",
             f"| rank of W | {d['rank']} | {s['rank']} |",
             f"| sigma_min of W | {d['sigma_min']:.3g} | {s['sigma_min']:.3g} |",
             f"| condition number of W | {cond(d['condition_number'])} | {cond(s['condition_number'])} |",
             f"| sources with expected std <= 1 % of range | {d['n_sources_below_1pct']} | "
             f"{s['n_sources_below_1pct']} |", "",
             *_avoided_lines(report.get("avoided")),
             *_kept_lines(report.get("kept")),
             "![expected standard errors](design.png)", "", "## Expected standard error per source [% of range]", "",
             "| source | designed | standard |", "|---|---:|---:|"]
    for name, a, b in zip(report["names"], d["expected_std_of_range"], s["expected_std_of_range"]):
        lines.append(f"| `{name}` | {100 * a:.3g} | {100 * b:.3g} |")
    return "\n".join(lines) + "\n"


def _drives_lines(drives: dict | None) -> list[str]:
    """The drive sources' A-criterion rows of the figure table (none without --criterion drives)."""
    if not drives:
        return []
    d, s = drives["designed"], drives["standard_trajectory"]
    return [f"| sum of (drive std / paper figure)^2 (drives criterion) | {d['trace']:.4g} | {s['trace']:.4g} |",
            f"| largest drive std / paper figure | {d['max_std_over_figure']:.3g} | {s['max_std_over_figure']:.3g} |"]


def _avoided_lines(avoided: dict | None) -> list[str]:
    if not avoided:
        return ["No posture avoided (--inadequacy none: the model's own error is not known here).", ""]
    median = avoided["avoided_model_error_urad"]["median"]
    return [f"Postures avoided: {avoided['n_avoided']} of {avoided['n_candidates']} candidates, those where the model's "
            f"expected error exceeds {avoided['max_model_error_urad']:.3g} urad on some angle"
            + ("" if median is None else f" (median {median:.3g} urad, up to "
               f"{avoided['avoided_model_error_urad']['max']:.3g} urad)")
            + f". Why: {avoided['why']}.", ""]


def _kept_lines(kept: dict | None) -> list[str]:
    if not kept:
        return []
    mm = lambda values: " / ".join(f"{v:.3g}" for v in values)  # noqa: E731
    return [f"Postures kept: the first {kept['n_kept']} are the {kept['n_kept']}-point standard trajectory (one actuator "
            f"at a time, strokes {mm(kept['kept_inputs_mm_max_abs'])} mm), then {kept['n_designed']} designed "
            f"(strokes up to {mm(kept['designed_inputs_mm_max_abs'])} mm). Why: {kept['why']}.", ""]


def plot_design(path, design, names) -> None:
    """design.png: the expected standard error per source [% of range], designed against the
    standard trajectory, with the prior alone and 1 % of range as lines."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(12, 4))
    index = np.arange(len(names))
    ax.semilogy(index, 100 * design.reference_quality.expected_std, "s", label="standard trajectory (77)", alpha=0.7)
    ax.semilogy(index, 100 * design.quality.expected_std, "o", label=f"designed ({design.inputs.shape[0]})")
    ax.axhline(100 / np.sqrt(12) * design.prior_scale, color="0.5", ls="--", lw=0.8, label="prior alone")
    ax.axhline(1.0, color="k", ls=":", lw=0.8, label="1 % of range")
    ax.set_xticks(index, names, rotation=90, fontsize=7)
    ax.set_ylabel("expected standard error [% of range]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
