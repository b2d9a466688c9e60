"""The model-form floor as report.md text (``runs.form_floor.model_form_floor``'s entry):
one table, a row per posture group, the run's model and the paper's at the true values
beside the fit, RMS per angle and the largest |error| [urad]."""

from __future__ import annotations

from typing import Any

__all__ = ["form_floor_markdown", "form_floor_line"]

ANGLES = ("theta_x", "theta_y", "theta_z")
ROWS = (("all", None, "all postures"), ("class", "S1", "S1"), ("class", "S2", "S2"), ("class", "S3", "S3"),
        ("actuators", "single", "single-actuator"), ("actuators", "multi", "multi-actuator"),
        ("unloading", "near", "near a drive's unloading"), ("unloading", "far", "away from unloading"))


def _pick(block: dict[str, Any], split: str, label: str | None) -> dict[str, Any]:
    return block["all"] if label is None else block[split][label]


def _cells(stats: dict[str, Any]) -> str:
    if not stats["n"]:
        return "— | —"
    rms = stats["rms_urad"]
    return " / ".join(f"{rms[a]:.3g}" for a in ANGLES) + f" | {stats['max_urad']:.3g}"


def form_floor_markdown(floor: dict[str, Any] | None) -> list[str]:
    """report.md lines of a ``model_form_floor`` entry (a heading, the truth, the table)."""
    lines = ["## Model-form floor (the model at the true values against the truth)", ""]
    if not floor or not floor.get("available"):
        return lines + [f"Model-form floor: {(floor or {}).get('reason', 'not available: no true values')}.", ""]
    models = floor["models"]
    lines += [f"Truth: {floor['truth']}; {floor['n_points']} postures. No identification can fit below the floor "
              "of the model it calibrates.", ""]
    lines += [f"- {'the run' if m['model'] == 'run' else 'paper'}: {m['description']}" for m in models] + [""]
    header = "| postures | n | " + " | ".join(
        f"{'run' if m['model'] == 'run' else 'paper'} model RMS θx / θy / θz | max" for m in models)
    if "fit" in floor:
        header += " | fit RMS θx / θy / θz | max"
    lines += [header + " |", "|---|---:|" + "---:|---:|" * (len(models) + ("fit" in floor))]
    for split, label, name in ROWS:
        blocks = [_pick(m, split, label) for m in models] + ([_pick(floor["fit"], split, label)] if "fit" in floor
                                                             else [])
        lines.append(f"| {name} | {blocks[0]['n']} | " + " | ".join(_cells(b) for b in blocks) + " |")
    groups = floor["groups"]
    lines += ["", "urad. Groups: class " + groups["class"] + "; actuators " + groups["actuators"] + "; unloading "
              + groups["unloading"] + ".", ""]
    return lines


def form_floor_line(floor: dict[str, Any] | None) -> str:
    """One line for the terminal: each model's floor RMS per angle and max [urad]."""
    if not floor or not floor.get("available"):
        return f"model-form floor: {(floor or {}).get('reason', 'not available: no true values')}"
    parts = []
    for m in floor["models"]:
        rms = m["all"]["rms_urad"]
        parts.append(f"{'run' if m['model'] == 'run' else 'paper'} model "
                     + " / ".join(f"{rms[a]:.2f}" for a in ANGLES) + f" urad RMS (max {m['all']['max_urad']:.2f})")
    return "model-form floor (θx / θy / θz, true values vs truth): " + "; ".join(parts)
