"""Figures of the gap diagnosis and of its blind benchmark (PNG, matplotlib Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["plot_residual", "plot_strata", "plot_heldout", "plot_benchmark"]

ANGLE_LABELS = ("θx", "θy", "θz")


def _pyplot():
    from ..reports.plots import _pyplot as pyplot

    return pyplot()


def plot_residual(path: Path, diagnosis, leg: np.ndarray) -> None:
    """Baseline residual and held-out residual after the accepted effects, per angle [urad]."""
    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    index = np.arange(1, diagnosis.residual.shape[0] + 1)
    for c, ax in enumerate(axes):
        ax.plot(index, diagnosis.heldout_before[:, c] * 1e6, lw=0.8, marker=".", ms=3, label="held out, baseline")
        ax.plot(index, diagnosis.heldout_after[:, c] * 1e6, lw=0.8, marker=".", ms=3,
                label="held out, + " + (", ".join(diagnosis.stages) or "nothing"))
        for boundary in np.flatnonzero(np.diff(leg)) + 1.5:
            ax.axvline(boundary, color="0.8", lw=0.6)
        ax.set_ylabel(f"{ANGLE_LABELS[c]} [µrad]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("data point (grey lines: leg boundaries)")
    fig.suptitle("held-out residual on left-out legs (measured − prediction)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_strata(path: Path, rows: list[dict], sigma_urad: np.ndarray) -> None:
    """Residual RMS per stratum (bars per angle), noise floor dashed."""
    plt = _pyplot()
    labels = [f"{r['by']}: {r['stratum']}" for r in rows]
    values = np.array([r["rms_urad"] for r in rows])
    fig, ax = plt.subplots(figsize=(9, max(3.0, 0.18 * len(rows) + 1)))
    y = np.arange(len(rows))
    for c in range(3):
        ax.barh(y + (c - 1) * 0.27, values[:, c], height=0.27, label=ANGLE_LABELS[c])
    ax.axvline(float(np.sqrt(np.mean(np.asarray(sigma_urad) ** 2))), color="k", ls="--", lw=0.8, label="noise floor")
    ax.set_yticks(y, labels, fontsize=6)
    ax.invert_yaxis()
    ax.set_xlabel("residual RMS [µrad]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_heldout(path: Path, ranking: list[dict]) -> None:
    """Held-out RMS per angle before and after each candidate term (stage 1)."""
    plt = _pyplot()
    names = [r["effect"] for r in ranking]
    before = np.array(ranking[0]["heldout_rms_before_urad"]) if ranking else np.zeros(3)
    after = np.array([r["heldout_rms_after_urad"] for r in ranking]) if ranking else np.zeros((0, 3))
    fig, ax = plt.subplots(figsize=(9, 3.8))
    x = np.arange(len(names))
    for c in range(3):
        ax.bar(x + (c - 1) * 0.27, after[:, c], width=0.27, label=f"after, {ANGLE_LABELS[c]}")
        ax.axhline(before[c], color=f"C{c}", ls="--", lw=0.8)
    ax.set_xticks(x, names, rotation=40, ha="right", fontsize=7)
    ax.set_ylabel("held-out RMS [µrad] (dashed: baseline)")
    ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_benchmark(directory: Path, rows: list[dict], summary: dict) -> None:
    """diagnosis_confusion.png, diagnosis_detection.png, diagnosis_closure.png."""
    plt = _pyplot()
    truths = list(dict.fromkeys(r["effect"] for r in rows))
    predicted = list(dict.fromkeys([*truths, *(r["predicted"] for r in rows)]))
    matrix = np.zeros((len(truths), len(predicted)))
    for r in rows:
        matrix[truths.index(r["effect"]), predicted.index(r["predicted"])] += 1
    fig, ax = plt.subplots(figsize=(9, 7))
    ax.imshow(matrix, cmap="Blues")
    for i in range(len(truths)):
        for j in range(len(predicted)):
            if matrix[i, j]:
                ax.text(j, i, f"{int(matrix[i, j])}", ha="center", va="center", fontsize=8)
    ax.set_xticks(range(len(predicted)), predicted, rotation=60, ha="right", fontsize=7)
    ax.set_yticks(range(len(truths)), truths, fontsize=7)
    ax.set_xlabel("diagnosed top effect")
    ax.set_ylabel("injected effect (answer file)")
    ax.set_title("blind benchmark: confusion matrix (all magnitudes)")
    fig.tight_layout()
    fig.savefig(Path(directory) / "diagnosis_confusion.png", dpi=110)
    plt.close(fig)

    fig, (ax, cases) = plt.subplots(1, 2, figsize=(10, 3.8))
    detection = summary["detection_by_magnitude"]
    ax.plot([float(m) for m in detection], list(detection.values()), marker="o", label="correct top effect / group")
    ax.axhline(0.9, color="k", ls="--", lw=0.8, label="goal (>= 3x)")
    ax.set_xlabel("injected magnitude (nominal) [x noise]")
    ax.set_ylabel("rate")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    # each library case at the magnitude really injected into its file: found or missed
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    from ..effects.library import EFFECT_IDS

    measured = [r for r in rows if r.get("achieved_magnitude_noise") is not None and r["effect"] in EFFECT_IDS]
    for correct, marker, label in ((True, "o", "found"), (False, "x", "missed")):
        at = [r for r in measured if bool(r["correct"]) == correct]
        if at:
            cases.scatter([r["achieved_magnitude_noise"] for r in at],
                          [truths.index(r["effect"]) for r in at], marker=marker, s=22,
                          color="C2" if correct else "C3", label=label)
    library = [t for t in truths if t in EFFECT_IDS]
    cases.set_yticks([truths.index(t) for t in library], library, fontsize=7)
    cases.set_xscale("log")
    cases.xaxis.set_major_locator(FixedLocator([0.5, 1, 2, 3, 5, 10, 20, 50, 100]))
    cases.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    cases.xaxis.set_minor_formatter(NullFormatter())
    cases.axvline(3.0, color="k", ls="--", lw=0.8)
    cases.set_xlabel("achieved signature RMS on the file [x noise]")
    cases.legend(fontsize=8)
    cases.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(Path(directory) / "diagnosis_detection.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    pairs = [(p["predicted_closure"], p["achieved_closure"]) for p in summary["predicted_vs_achieved"]
             if p["predicted_closure"] is not None and p["achieved_closure"] is not None]
    if pairs:
        pred, ach = np.array(pairs).T
        ax.scatter(pred, ach, s=14)
    ax.plot([0, 1], [0, 1], color="0.6", lw=0.8)
    ax.axhline(0.7, color="k", ls="--", lw=0.8, label="goal 0.7")
    ax.set_xlabel("closure of the diagnosed winner (held-out legs)")
    ax.set_ylabel("closure of the injected effect's term")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(Path(directory) / "diagnosis_closure.png", dpi=110)
    plt.close(fig)
