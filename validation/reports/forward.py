"""The picture of one posture (``flexcal forward`` and ``flexcal inverse`` with ``--out``):
rendering only; the numbers are ``cli.forward.point_report``'s."""

from __future__ import annotations

__all__ = ["plot_point"]


def plot_point(report: dict, path, title: str) -> None:
    """point.png: the frame's rotation [urad] and every chain's axial load [N] at the point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    left.bar(["θx", "θy", "θz"], report["theta_urad"], color="tab:blue")
    left.set_ylabel("rotation [µrad]")
    left.axhline(0.0, color="black", lw=0.8)
    names, loads = list(report["axial_load_N"]), list(report["axial_load_N"].values())
    right.bar(names, loads, color=["tab:red" if v > 0 else "tab:green" for v in loads])
    right.axhline(0.0, color="black", lw=0.8)
    right.set_ylabel("axial load [N] (red: tension, green: compression)")
    fig.suptitle(f"{title}: class {report['point_class']}, inputs "
                 + ", ".join(f"{v:.4g}" for v in report["inputs_mm"]) + " mm", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
