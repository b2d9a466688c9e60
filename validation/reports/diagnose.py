"""``flexcal diagnose``'s report.md and terminal numbers, from its report (rendering only;
the diagnosis is ``diagnosis/diagnose.py``)."""

from __future__ import annotations

from .form_floor import form_floor_markdown
from .safe_markdown import md_text

__all__ = ["markdown", "fmt3"]


def fmt3(values) -> str:
    """Numbers as "a, b, c", three significant digits each."""
    return ", ".join(f"{v:.3g}" for v in values)


def _noise_test_lines(report) -> list[str]:
    """The correlated-noise test (diagnosis.correlated): how the answer was found, its z and p."""
    test = report.get("correlated_noise")
    if not test:
        return []
    if not test["available"]:
        return [f"Correlated-noise test: not available ({test['n_pairs']} pairs of repeated readings).", ""]
    found = {"correlated noise": " (the answer: no term was significant)",
             "heldout and correlated noise": " after the accepted effects (the noise joins the winner's group: a term smooth "
                                             "in time takes the slow part of a correlated noise)"}.get(report.get("detected_by"), "")
    return [f"Correlated-noise test on what is left (repeated readings, {test['n_pairs']} pairs): z {test['z']:.2f}, "
            f"p {test['p_value']:.2g} against {test['alpha']:g}: "
            f"{'correlated, not repeated' if test['correlated'] else 'white'}{found}.", ""]


def markdown(report) -> str:
    """report.md of a diagnosis report."""
    lines = ["# Sim-to-real gap diagnosis", "",
             f"**Top effect: `{report['top_effect']}`** (confidence {report['confidence']}"
             + (f"; indistinguishable group: {', '.join(report['top_group'])}" if len(report["top_group"]) > 1 else "")
             + f"). Effects added in turn: {', '.join(report['accepted_effects']) or 'none'}.", "",
             *_separation_lines(report),
             *_noise_test_lines(report),
             f"Noise floor {report['noise_floor_urad']:.3g} urad ({fmt3(report['noise_floor_per_angle_urad'])} per "
             f"angle; {report['noise_floor']['method']}).", "",
             f"Baseline: {report['baseline']['description']}; in-sample RMS {fmt3(report['baseline']['in_sample_rms_urad'])}"
             f" urad. Held-out unit: {report['heldout']['unit']} ({report['heldout']['n_folds']} folds).", "",
             "## How far", "",
             f"Held-out RMS per angle {fmt3(report['how_far']['heldout_rms_before_urad'])} -> "
             f"{fmt3(report['how_far']['heldout_rms_after_urad'])} urad; closure "
             f"{report['how_far']['closure']:.2f} of the gap above the noise floor.", "",
             "## Ranking (stage 1: each term added to the baseline alone)", "",
             "| effect | closure | gain [noise var] | dAICc | dBIC | held-out RMS before | after | significant |",
             "|---|---:|---:|---:|---:|---|---|---|"]
    for r in report["ranking"]:
        lines.append(f"| {r['effect']} | {r['closure']:.3f} | {r['gain_noise_variances']:.2f} | {r['delta_aicc']:.1f} | "
                     f"{r['delta_bic']:.1f} | {fmt3(r['heldout_rms_before_urad'])} | "
                     f"{fmt3(r['heldout_rms_after_urad'])} | {'yes' if r['significant'] else 'no'} |")
    lines += ["", "## Where", "", f"Overall residual RMS {fmt3(report['where']['overall_rms_urad'])} urad, max "
              f"{fmt3(report['where']['max_abs_urad'])} urad.", ""]
    concentrated = report["where"]["concentrated"]
    if concentrated:
        lines += ["Concentrated in:", ""] + [
            f"- {md_text(c['by'])} {md_text(c['stratum'])}, {c['angle']}: {c['rms_urad']:.3g} urad "
            f"({c['ratio_to_overall']:.2f}x overall)"
            for c in concentrated[:12]]
    else:
        lines.append("No stratum stands out (no RMS above 1.5x overall and 2 noise floors).")
    lines += ["", "| angle | runs z | lag-1 autocorrelation (z) | period [points] | Fisher p |", "|---|---:|---:|---:|---:|"]
    for s in report["where"]["structure"]:
        lines.append(f"| {s['angle']} | {s['runs_z']:.2f} | {s['lag1_autocorrelation']:.2f} ({s['lag1_z']:.1f}) | "
                     f"{s['period_points']:.1f} | {s['p_value']:.2g} |")
    absorbed = report["collinearity"]["absorbed_by_baseline"]
    lines += ["", "## Collinearity", "", "Share of each term's signature the baseline's 45 sources can mimic "
              "(1 = indistinguishable from a calibration error): " +
              ", ".join(f"{k} {v:.2f}" for k, v in absorbed.items()) + ".", ""]
    if report["undetectable"]:
        lines.append(f"Undetectable on this trajectory (absorbed >= 0.99 by the baseline's sources): "
                     f"{', '.join(report['undetectable'])}.")
    if report["skipped_terms"]:
        lines.append(f"Skipped (column missing): {', '.join(report['skipped_terms'])}.")
    if "model_form_floor" in report:
        lines += [""] + form_floor_markdown(report["model_form_floor"])
    return "\n".join(lines) + "\n"


def _separation_lines(report) -> list[str]:
    """The look-alike test of the confidence and the null of the trajectory, in words."""
    lines = []
    separation = report.get("separation")
    if separation:
        verdict = "separated" if separation["separated"] else "NOT separated: confidence lowered to low"
        second = separation.get("runner_up")
        closest = separation.get("closest")
        lines += ["Look-alikes (leave one effect out): " +
                  (f"on a signature of `{closest}`'s kind of the same size the winner would close "
                   f"{separation['closure_on_closest']:.2f} of the held-out gap" if closest else
                   "no other effect's signature space meets the winner's")
                  + (f"; on the data `{second['effect']}` closes {second['ratio']:.2f} of what the winner closes"
                     if second else "") + f" ({verdict}).", ""]
    null = report.get("null")
    if null:
        raised = {k: v for k, v in null["min_gain"].items() if v > report["criteria"]["min_gain_noise"]}
        lines += [f"Null of the trajectory ({null['n_files']} `none` files): gain thresholds raised for "
                  + (", ".join(f"{k} {v:.2f}" for k, v in raised.items()) or "no term") + " [noise variances].", ""]
    return lines
