"""``flexcal sensitivity``'s report.md and sensitivity.png (Fig. 5), from its Sobol indices
(rendering only; the screening is ``cli.sensitivity.screen``)."""

from __future__ import annotations

__all__ = ["sensitivity_markdown", "write_sensitivity_figure"]


def sensitivity_markdown(sobol, *, n_points: int, seed: int, threshold: float, selected) -> str:
    """report.md of ``flexcal sensitivity``: the setting, the selected sources and the
    sources ranked by the overall total index."""
    from flexcal.calibration.sensitivity import format_ranked_table

    return "\n".join(["# Sobol screening of the 45 error sources", "",
                      f"{n_points} postures; N = {sobol.n_base} ({sobol.n_evaluations} model runs), sample seed "
                      f"{seed}. Output: the model's deviation from the ideal small-deflection model "
                      f"(overall Eq. 13 norm and per angle).", "",
                      f"Sources with a total index >= {threshold:g} on any output, plus the nine Table 1 "
                      f"drive sources ({len(selected)}): " + ", ".join(f"`{n}`" for n in selected), "",
                      "![Normalized total Sobol indices (Fig. 5)](sensitivity.png)", "",
                      "## Ranked by the overall total index", "", format_ranked_table(sobol, 0)])


def write_sensitivity_figure(directory, sobol) -> None:
    """sensitivity.png: the normalized total Sobol indices (Fig. 5) in ``directory``."""
    from flexcal.calibration.plots import plot_sensitivity

    plot_sensitivity(sobol, directory / "sensitivity.png")
