"""A sweep's table (CSV), summary (JSON) and plots, written from the finished records.

sweep.csv: one row per design of the config (failed designs: empty result cells), columns
``id``, the dimensions [mm], ``n_nodes``, the FEM and closed-form diagonal compliances
(SI), their discrepancy [%], the peak stress per unit rotation [MPa/mrad] (FEM and
nominal) and their ratio, identification accuracy when computed. discrepancy.png and
stress.png: those against each swept dimension. report.json: a summary, the effective
config, the ids computed in this run and the failures; timings.json: the wall-clock
seconds of the run and of each design (``output.write_report``).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

from ..output import atomic_path, write_report, write_text
from ..reports.safe_markdown import md_text
from .job import DIAGONAL
from .space import DEFAULT_CONFIG, resolve_config, varied_names

__all__ = ["table_rows", "write_tables", "plot_sweep"]

_MPA_PER_MRAD = 1e-6 * 1e-3  # [Pa/rad] -> [MPa/mrad]


def table_rows(records: list[dict[str, Any] | None], designs_ids: list[str], kind: str) -> list[dict[str, Any]]:
    """Flat rows for the CSV (plain numbers, '' for a failed design's results)."""
    rows = []
    for identifier, record in zip(designs_ids, records):
        row: dict[str, Any] = {"id": identifier}
        if record is None:
            rows.append(row)
            continue
        design = record["design"]
        row.update({name: design[name] for name in DEFAULT_CONFIG[kind]})
        row["elements_through"] = design["elements_through"]
        row["n_nodes"] = record["n_nodes"]
        c_fem, c_ana = np.array(record["compliance_fem"]), np.array(record["compliance_closed_form"])
        for k, name in enumerate(DIAGONAL):
            row[f"C_{name}_fem"] = c_fem[k, k]
            row[f"C_{name}_closed_form"] = c_ana[k, k]
        row.update({f"discrepancy_{name}_percent": record["discrepancy_percent"][name] for name in DIAGONAL})
        row["stress_per_rotation_fem_MPa_per_mrad"] = record["stress_per_rad_fem"] * _MPA_PER_MRAD
        row["stress_per_rotation_nominal_MPa_per_mrad"] = record["stress_per_rad_nominal"] * _MPA_PER_MRAD
        row["stress_concentration"] = record["stress_per_rad_fem"] / record["stress_per_rad_nominal"]
        if "structure" in record:  # a chain: MPa per mm of B's sideways stroke (Pa/m x 1e-9)
            structure = record["structure"]
            row["first_frequency_clamped_Hz"] = structure["first_frequency_clamped_hz"]
            row["stress_per_lateral_stroke_y_MPa_per_mm"] = structure["stress_per_m_lateral_y"] * 1e-9
            row["stress_per_lateral_stroke_z_MPa_per_mm"] = structure["stress_per_m_lateral_z"] * 1e-9
            row["buckling_load_sway_kN"] = structure["buckling_load_sway_n"] * 1e-3
            row["buckling_factor"] = structure["buckling_factor"]
        if "identification" in record:
            row.update({f"identification_{k}": v for k, v in record["identification"].items()
                        if isinstance(v, (int, float))})
        rows.append(row)
    return rows


def plot_sweep(rows: list[dict[str, Any]], names: list[str], folder: Path) -> list[str]:
    """discrepancy.png and stress.png against each swept dimension; returns file names."""
    done = [r for r in rows if "n_nodes" in r]
    if not done or not names:
        return []
    discrepancy = [(f"discrepancy_{entry}_percent", f"C {entry.replace('_', ',')}") for entry in DIAGONAL]
    stress = [(f"stress_per_rotation_{key}_MPa_per_mrad", label)
              for key, label in (("fem", "FEM peak von Mises"), ("nominal", "beam theory 6/(b t² C_rz,Mz)"))]
    _plot_against(done, names, discrepancy, "FEM vs closed form [%]",
                  "Compliance discrepancy FEM vs closed form (diagonal entries)", folder / "discrepancy.png", zero=True)
    _plot_against(done, names, stress, "stress per rotation [MPa/mrad]", "Peak stress per unit rotation about z",
                  folder / "stress.png")
    return ["discrepancy.png", "stress.png"]


def _plot_against(done: list[dict[str, Any]], names: list[str], series: list[tuple[str, str]], ylabel: str,
                  title: str, path: Path, *, zero: bool = False) -> None:
    """One panel per swept dimension, each ``(column, label)`` of ``series`` against it."""
    from ..reports.plots import _pyplot

    plt = _pyplot()
    fig, axes = plt.subplots(1, len(names), figsize=(5.5 * len(names), 4), squeeze=False)
    for ax, name in zip(axes[0], names):
        order = np.argsort([r[name] for r in done])
        x = np.array([done[i][name] for i in order])
        for column, label in series:
            ax.plot(x, [done[i][column] for i in order], marker="o", lw=1, label=label)
        if zero:
            ax.axhline(0.0, color="k", lw=0.6)
        ax.set_xlabel(name)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def write_tables(result, config: dict[str, Any], out: Path) -> None:
    """OUT/sweep.csv, OUT/report.json, OUT/timings.json, OUT/report.md and the plots, each written atomically."""
    kind = resolve_config(config)["sweep"]["kind"]
    rows = table_rows(result.records, list(result.ids), kind)
    columns: list[str] = []
    for row in rows:
        columns += [c for c in row if c not in columns]
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "sweep.csv") as tmp:
        with open(tmp, "w", newline="") as stream:
            writer = csv.DictWriter(stream, fieldnames=columns, restval="")
            writer.writeheader()
            writer.writerows(rows)
    figures = plot_sweep(rows, varied_names(config), out)
    done = [r for r in result.records if r is not None]
    write_report(out, {
        "summary": {"kind": kind, "n_designs": len(rows), "n_finished": len(done),
                    "n_computed_this_run": len(result.computed), "n_failed": len(result.failures),
                    "max_abs_discrepancy_rz_Mz_percent": max((abs(r["discrepancy_percent"]["rz_Mz"]) for r in done),
                                                             default=None),
                    "wall_s": result.wall_s},
        "config": resolve_config(config),
        "n_designs": len(rows),
        "n_finished": sum(r is not None for r in result.records),
        "computed_this_run": list(result.computed),
        "failures": result.failures,
        "wall_s": result.wall_s,
        "timings_s": {"designs": {identifier: record["wall_s"] for identifier, record in zip(result.ids, result.records)
                                  if record is not None}},
        "files": ["sweep.csv", "report.md", "timings.json", *figures, "designs/<id>.json"],
        "columns": columns,
    })
    write_text(out / "report.md", sweep_markdown(rows, kind, figures, len(done), len(result.failures)))


def sweep_markdown(rows: list[dict[str, Any]], kind: str, figures: list[str], n_finished: int, n_failed: int) -> str:
    """report.md: the table of the designs (the CSV's leading columns) and the plots."""
    lines = [f"# Sweep of {md_text(kind)} designs", "",
             f"{len(rows)} designs, {n_finished} finished, {n_failed} failed. Full table: `sweep.csv`.", ""]
    if rows:
        shown = [c for c in rows[0] if not c.startswith("C_")][:12]
        lines += ["| " + " | ".join(map(md_text, shown)) + " |", "|" + "---|" * len(shown)]
        for row in rows:
            cells = [f"{row.get(c, ''):.4g}" if isinstance(row.get(c), float) else md_text(row.get(c, "")) for c in shown]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    lines += [f"![{name}]({name})" for name in figures]
    return "\n".join(lines) + "\n"
