"""Figures of the calibration step (PNG, matplotlib's Agg canvas, no pyplot state).

- ``plot_sensitivity``: normalized total Sobol indices per parameter, one panel per
  output (overall and per angle), like the paper's Fig. 5(a-b);
- ``plot_convergence``: best fitness per iteration of one or several PSO runs (Fig. 7d)
  and, for the improved PSO, the local best of every subgroup (Fig. 11).

Each writes its file whole or not at all (``flexcal.geometry.atomic.atomic_path``).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np

from flexcal.calibration.pso import PSOResult
from flexcal.calibration.sensitivity import SobolResult
from flexcal.geometry.atomic import atomic_path

__all__ = ["plot_sensitivity", "plot_convergence"]


def _save(fig, path: str | os.PathLike) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"figure path {path} must end in .png")
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=150)
    return path


def plot_sensitivity(result: SobolResult, path: str | os.PathLike, *, title: str | None = None) -> Path:
    """Bar chart of normalized ST (ST / sum ST) per parameter, one panel per output,
    with the 95 % confidence half-width scaled the same way as error bars. Returns path."""
    from matplotlib.figure import Figure

    norm = result.normalized_ST()
    total = np.clip(result.ST, 0.0, None).sum(axis=1, keepdims=True)
    err = np.divide(result.ST_conf, total, out=np.zeros_like(result.ST_conf), where=total > 0)
    k, d = norm.shape
    fig = Figure(figsize=(max(6.0, 0.22 * d + 2.0), 1.8 + 1.9 * k), layout="constrained")
    axes = fig.subplots(k, 1, sharex=True, squeeze=False)[:, 0]
    index = np.arange(d)
    for row, ax in enumerate(axes):
        ax.bar(index, norm[row], yerr=err[row], color="tab:blue", ecolor="0.4", capsize=1.5, width=0.75)
        ax.set_ylabel(f"ST norm.\n{result.outputs[row]}")
        ax.set_ylim(bottom=0.0)
        ax.grid(axis="y", alpha=0.3)
    axes[-1].set_xticks(index, result.names, rotation=90, fontsize=7)
    axes[0].set_title(title or f"Total Sobol indices, normalized (N = {result.n_base}, "
                               f"{result.n_evaluations} runs)")
    return _save(fig, path)


def plot_convergence(runs: PSOResult | Mapping[str, PSOResult], path: str | os.PathLike, *,
                     ylabel: str = "fitness", title: str | None = None) -> Path:
    """Best fitness per iteration (log scale) of each run; a second panel with the local
    best of every subgroup of the first run that has subgroups. Returns path."""
    from matplotlib.figure import Figure

    if isinstance(runs, PSOResult):
        runs = {"improved PSO": runs}
    with_groups = next((r for r in runs.values() if r.subgroups), None)
    fig = Figure(figsize=(7.0, 3.2 if with_groups is None else 5.8), layout="constrained")
    axes = fig.subplots(2 if with_groups is not None else 1, 1, squeeze=False)[:, 0]
    def positive(y):  # the log axis shows finite positive values only
        y = np.asarray(y, float)
        return np.where(np.isfinite(y) & (y > 0), y, np.nan)

    for name, run in runs.items():
        it = np.arange(1, run.history_best_f.size + 1)
        axes[0].plot(it, positive(run.history_best_f), label=f"{name} (best {run.f_best:.3g})")
        for t in run.stagnation_iterations:
            axes[0].axvline(t, color="0.8", lw=0.8, zorder=0)
    axes[0].set_yscale("log")
    axes[0].set_ylabel(ylabel)
    axes[0].set_xlabel("iteration")
    axes[0].legend(fontsize=8)
    axes[0].set_title(title or "Convergence (grey lines: stagnation, subgroups isolated)")
    if with_groups is not None:
        ax = axes[1]
        for g in with_groups.subgroups:
            it = g.created_at + np.arange(1, g.history.size + 1)
            ax.plot(it, positive(g.history), lw=1.0, label=f"subgroup {g.index + 1}")
        ax.plot(np.arange(1, with_groups.history_global_f.size + 1), positive(with_groups.history_global_f),
                color="k", lw=0.8, ls="--", label="global swarm")
        ax.set_yscale("log")
        ax.set_xlabel("iteration")
        ax.set_ylabel(f"local best {ylabel}")
        ax.legend(fontsize=7, ncol=3)
    return _save(fig, path)
