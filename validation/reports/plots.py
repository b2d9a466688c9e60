"""Figures shared by the commands (matplotlib, Agg backend, PNG).

Plot functions take plain arrays in SI and write one PNG; they never compute physics.
"""

from __future__ import annotations

import os
from typing import Sequence

import numpy as np

__all__ = ["plot_misalignment_curves", "CLASS_COLOURS"]

CLASS_COLOURS = {"S1": "#1f77b4", "S2": "#d62728", "S3": "#2ca02c"}
ANGLE_LABELS = ("θx (rotation)", "θy (tip)", "θz (tilt)")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_misalignment_curves(
    path: str | os.PathLike,
    misalignment: np.ndarray,
    point_class: Sequence[str],
    *,
    leg: np.ndarray | None = None,
    fitted: np.ndarray | None = None,
    title: str = "",
) -> None:
    """Three stacked panels (θx, θy, θz) of misalignment [rad] against the point index,
    markers coloured by point class S1/S2/S3, leg boundaries as dotted lines, and an
    optional fitted curve (same shape, (n, 3) [rad]). Written in µrad.
    """
    plt = _pyplot()
    misalignment = np.asarray(misalignment) * 1e6
    n = misalignment.shape[0]
    index = np.arange(1, n + 1)
    classes = np.asarray(point_class)
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for k, ax in enumerate(axes):
        ax.plot(index, misalignment[:, k], color="0.6", lw=1, zorder=1)
        for name, colour in CLASS_COLOURS.items():
            mask = classes == name
            if mask.any():
                ax.scatter(index[mask], misalignment[mask, k], s=18, color=colour, label=name, zorder=2)
        if fitted is not None:
            ax.plot(index, np.asarray(fitted)[:, k] * 1e6, color="k", lw=1, ls="--", label="fit", zorder=3)
        if leg is not None:
            for boundary in np.flatnonzero(np.diff(np.asarray(leg)) != 0):
                ax.axvline(boundary + 1.5, color="0.8", ls=":", lw=1)
        ax.set_ylabel(f"{ANGLE_LABELS[k]}\nmisalignment [µrad]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8, ncol=4)
    axes[-1].set_xlabel("sampling point")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
