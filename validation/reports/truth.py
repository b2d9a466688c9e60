"""``flexcal truth``'s report.md and curves.png, from the prototype run (rendering only; the
curves are ``prototype.truth.make_truth``'s)."""

from __future__ import annotations

from .safe_markdown import md_text

__all__ = ["truth_markdown", "write_truth_figure"]

_ANGLES = ("θx", "θy", "θz")


def truth_markdown(scenario, n_points: int, classes, counts, injected, max_misalignment) -> str:
    """report.md of ``flexcal truth``: the point classes, the injected effects and the largest
    |measured − ideal model| per angle (max_misalignment (3,) [urad])."""
    return (f"# Virtual prototype: scenario {md_text(scenario.name)} (seed {scenario.seed})\n\n"
            f"{n_points} points; classes " + ", ".join(f"{c} {n}" for c, n in zip(classes, counts))
            + (f"; injected effects: {', '.join(map(md_text, injected))}" if injected else "; no injected effects")
            + ".\n\nMax |measured − ideal model| [urad]: "
            + ", ".join(f"{a} {v:.2f}" for a, v in zip(_ANGLES, max_misalignment))
            + ".\n\n![curves](curves.png)\n\nData: `curves.csv` with its sidecar `curves.json` "
              "(docs/prototype.md).\n")


def write_truth_figure(directory, scenario, misalignment, point_class, leg) -> None:
    """curves.png: the three misalignment curves (measured − ideal model [rad]), each point
    coloured by its class."""
    from .plots import plot_misalignment_curves

    plot_misalignment_curves(directory / "curves.png", misalignment, point_class, leg=leg,
                             title=f"virtual prototype, scenario {scenario.name} (seed {scenario.seed}): "
                                   f"measured − ideal model")
