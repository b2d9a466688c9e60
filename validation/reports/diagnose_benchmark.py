"""The report.md of ``flexcal diagnose-benchmark`` (the blind benchmark of the gap
diagnosis): goals, detection, failed cases and every case's row, from report.json's data."""

from __future__ import annotations

__all__ = ["benchmark_markdown"]


def _number(value, digits: int = 1) -> str:
    return "" if value is None else f"{value:.{digits}f}"


def _trajectory_text(trajectory: dict) -> str:
    if trajectory["kind"] == "standard":
        return "standard trajectory"
    from .safe_markdown import md_text

    return (f"trajectory {md_text(trajectory['file'])} ({trajectory['n_points']} points, {trajectory['n_legs']} legs, "
            f"sha256 {trajectory['sha256']})")


def _baseline_text(baseline: dict) -> str:
    """The diagnosis baseline's model in words (``cli.opening.model_key``'s table)."""
    model = baseline.get("model", "second-order")
    terms = f", {baseline['dimension_terms']} dimension terms" if model == "consistent" else ""
    return f"{model} model, {baseline['stiffness']} chain stiffness{terms}"


def benchmark_markdown(report) -> str:
    """report.md of a benchmark ``report`` (report.json's data)."""
    from .safe_markdown import md_text

    s = report["summary"]
    lines = ["# Blind benchmark of the gap diagnosis", "",
             f"Grid `{report['grid']}`, prototype provider `{report['provider']}` (diagnosis baseline: "
             f"{_baseline_text(report['baseline_model'])}), noise {report['noise_urad']} urad, "
             f"{_trajectory_text(report['trajectory'])} x{report['cycles']}"
             f"{'' if report.get('mount') is None else ', mount ' + md_text(report['mount'])}; "
             f"{len(report['rows'])} cases. "
             f"Out-of-library effects "
             f"(no model term): {', '.join(report['out_of_library'])}.", "", "## Goals", "",
             "| goal | target | measured | met | margin |", "|---|---:|---:|---|---:|"]
    for name, g in s["goals"].items():
        lines.append(f"| {name} | {g['goal']:.2f} | {g['measured']:.3f} | {'yes' if g['met'] else 'NO'} | "
                     f"{g['margin']:+.3f} |")
    if s.get("detection_at_achieved_3x_or_more") is not None:
        lines += ["", f"Detection by the magnitude really injected into each file (noise-free signature RMS, the "
                  f"effect's run minus the same mount without it) >= 3x noise: "
                  f"{s['detection_at_achieved_3x_or_more']:.3f} of {s['n_at_achieved_3x_or_more']} cases."]
    lines += ["", f"Detection at >= 3x counting only effects the diagnosis did not report as undetectable "
              f"(absorbed >= 0.99 by the baseline): {s['detection_at_3x_excluding_reported_undetectable']:.3f} "
              f"({s['n_reported_undetectable_at_3x']} cases reported undetectable).", ""]
    lines += ["", f"Out-of-library: no confident library claim in {s['out_of_library_no_confident_claim']} of cases; "
              f"a concentrated stratum named in {s['out_of_library_where_named']}.", "",
              "## Detection by magnitude (x noise)", ""]
    lines += [f"- {m}x: {v:.2f}" for m, v in s["detection_by_magnitude"].items()]
    if report["failures"]:
        lines += ["", f"## Failed cases ({len(report['failures'])}; not in the figures)", ""]
        lines += [f"- {md_text(label)}: {md_text(text)}" for label, text in report["failures"].items()]
    lines += ["", "## Cases", "", "| effect | x noise | seed | predicted | group | confidence | correct | "
              "true-term closure | absorbed by baseline | achieved x noise |", "|---|---:|---:|---|---|---|---|---:|---:|---:|"]
    for r in report["rows"]:
        closure, absorbed = _number(r.get("true_term_closure"), 2), _number(r.get("absorbed"), 3)
        lines.append(f"| {r['effect']} | {r['magnitude_noise']:g} | {r['seed']} | {r['predicted']} | "
                     f"{', '.join(r['group'])} | {r['confidence']} | {'yes' if r['correct'] else 'no'} | "
                     f"{closure} | {absorbed} | {_number(r.get('achieved_magnitude_noise'))} |")
    return "\n".join(lines) + "\n"
