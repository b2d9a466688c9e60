"""The workspace part of ``flexcal structure``'s report: peak stresses (and where) at the
workspace corners and along the standard trajectory, their change under one mesh
refinement (FEM segments), the support stiffness at the corners, and each actuator's
stress-limited stroke (``flexcal.validation.structure.workspace``; docs/structure.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..prototype.mechanism import Prototype
from .workspace import StressAt, commands_for_angles, frame_angles, stress_at, stroke_limit, workspace_corners

__all__ = ["DESIGN_SAFETY", "REFINED_CHAINS", "workspace_section", "trajectory_peaks", "workspace_markdown"]

DESIGN_SAFETY = 2.0
"""Safety factor on yield for the design stroke: the calibration repeats its strokes
(fatigue: a steel's fully reversed endurance limit is ~half its tensile strength, for
S355 ~235-250 MPa, i.e. yield / ~1.4) and the beam bound leaves out the fillets' stress
concentration (K_t ~ 1.1-1.2; fTetWild's 2-through mesh under-resolved it by a few %, the
mapped mesh's peaks move by <= 0.5 % under one refinement): 1.4 x 1.2-1.3 ~ 1.8, rounded
up to 2."""


REFINED_CHAINS = (3, 4, 5)
"""The chains whose FEM stresses are refined: the driving chains D1-D3, which govern the
safety (one refinement of the mapped mesh, 8 cells through, is ~140k DOF per leaf
segment; the load chains' would double the builds)."""


def _mpa(names, values):
    return None if values is None else {n: (float(v) / 1e6 if np.isfinite(v) else None) for n, v in zip(names, values)}


def _stress_entry(names, at: StressAt, fine: StressAt | None) -> dict[str, Any]:
    entry = {"beam_MPa": _mpa(names, at.beam), "beam_where": dict(zip(names, at.beam_where)),
             "fem_MPa": _mpa(names, at.fem), "fem_where": None if at.fem_where is None else dict(zip(names, at.fem_where))}
    if fine is not None:
        entry["fem_refined_MPa"] = _mpa(names, fine.fem)
        entry["fem_refined_where"] = dict(zip(names, fine.fem_where))
    return entry


def trajectory_peaks(prototype: Prototype, commands: np.ndarray, fem=None, fem_fine=None) -> dict[str, Any]:
    """Largest stress per chain over the states at ``commands`` (n, 3) [m] (solved in
    order, each from the last), with the point index and the place of each: "beam",
    "fem", "fem_refined" -> {"stress" (6,) [Pa], "point" (6,), "where" (6,)} (None where
    there is no such source)."""
    from .mount import nominal_state

    sources = {"beam": None, "fem": fem, "fem_refined": fem_fine}
    best = {k: {"stress": np.zeros(6), "point": np.zeros(6, int), "where": [""] * 6} for k in sources}
    if fem_fine is not None:  # chains not refined stay NaN
        best["fem_refined"]["stress"][np.setdiff1d(np.arange(6), REFINED_CHAINS)] = np.nan
    poses = None
    for i, command in enumerate(commands):
        state = nominal_state(prototype, commands=command, start=poses)
        poses = state.poses
        at = stress_at(prototype, state, fem)
        fine = stress_at(prototype, state, fem_fine, REFINED_CHAINS) if fem_fine is not None else None
        for name, values, where in (("beam", at.beam, at.beam_where), ("fem", at.fem, at.fem_where),
                                    ("fem_refined", None if fine is None else fine.fem,
                                     None if fine is None else fine.fem_where)):
            if values is None:
                continue
            for c in np.flatnonzero(np.nan_to_num(values, nan=-1.0) > best[name]["stress"]):
                best[name]["stress"][c], best[name]["point"][c], best[name]["where"][c] = values[c], i, where[c]
    return {k: (v if sources[k] is not None or k == "beam" else None) for k, v in best.items()}


def workspace_section(prototype: Prototype, *, fem=None, fem_fine=None, trajectory_commands: np.ndarray | None = None,
                      nominal_stiffness: np.ndarray | None = None, safety: float = DESIGN_SAFETY) -> dict[str, Any]:
    """The report's "workspace" dict (module docstring). ``fem``/``fem_fine``:
    ``FemSegments`` at the report's mesh and one refinement (or None);
    ``trajectory_commands`` (n, 3) [m] or None; ``nominal_stiffness`` (6, 6) the support
    stiffness at the nominal state, for the corners' ratios."""
    from .mount import nominal_state, support_stiffness

    names = [c.name for c in prototype.mechanism.chains]
    yield_strength = prototype.mechanism.material.yield_strength
    corners = workspace_corners(prototype.mechanism)
    commands, states = commands_for_angles(prototype, corners)
    theta0 = frame_angles(nominal_state(prototype))
    corner_rows = []
    for corner, command, state in zip(corners, commands, states):
        at = stress_at(prototype, state, fem)
        fine = stress_at(prototype, state, fem_fine, REFINED_CHAINS) if fem_fine is not None else None
        k = support_stiffness(prototype, state.tangent)
        corner_rows.append({"angles_mrad": (1e3 * corner).tolist(), "commands_mm": (1e3 * command).tolist(),
                            "reached_mrad": (1e3 * (frame_angles(state) - theta0)).tolist(),
                            "axial_load_N": dict(zip(names, state.tension.tolist())),
                            **_stress_entry(names, at, fine), "support_stiffness_diagonal": np.diag(k).tolist()})
    out: dict[str, Any] = {"corners": corner_rows}
    source = "fem_MPa" if fem is not None else "beam_MPa"
    corner_peak = {n: max(row[source][n] for row in corner_rows) for n in names}
    out["corner_peak_MPa"] = corner_peak
    out["safety_factor_at_corners"] = {n: yield_strength / 1e6 / v for n, v in corner_peak.items()}
    diagonals = np.array([row["support_stiffness_diagonal"] for row in corner_rows])
    if nominal_stiffness is not None:
        nominal = np.diag(nominal_stiffness)
        worst = int(np.argmin((diagonals / nominal).min(axis=1)))
        out["support_stiffness"] = {
            "nominal_diagonal": nominal.tolist(), "min_over_corners": diagonals.min(axis=0).tolist(),
            "max_over_corners": diagonals.max(axis=0).tolist(),
            "worst_corner": worst, "worst_corner_ratio": (diagonals[worst] / nominal).tolist(),
            "what": "diagonal of the 6 x 6 at O_C (nuts held); worst corner: the one with the smallest ratio of a "
                    "diagonal term to its nominal value"}
    if trajectory_commands is not None:
        peaks = trajectory_peaks(prototype, trajectory_commands, fem, fem_fine)
        out["trajectory"] = {name: None if v is None else {
            "MPa": _mpa(names, v["stress"]), "point": dict(zip(names, v["point"].tolist())),
            "commands_mm": {n: (1e3 * trajectory_commands[p]).tolist() for n, p in zip(names, v["point"])},
            "where": dict(zip(names, v["where"]))} for name, v in peaks.items()}

    def peak(state):
        return float(stress_at(prototype, state, fem).governing.max())

    limits = {"yield": yield_strength, f"yield/{safety:g}": yield_strength / safety}
    out["stroke_limit_mm"] = {
        "what": "command of one actuator (others at zero) at which the largest peak stress over all chains "
                f"({'FEM' if fem is not None else 'beam bound'}) reaches the limit; + and - directions",
        "design_safety_factor": safety,
        **{label: {f"actuator {i + 1}": {"+": 1e3 * stroke_limit(prototype, i, 1.0, value, peak),
                                         "-": 1e3 * stroke_limit(prototype, i, -1.0, value, peak)}
                   for i in range(3)} for label, value in limits.items()}}
    return out


def _cell(table, name, digits=3):
    return "-" if table is None or table[name] is None else f"{table[name]:.{digits}g}"


def workspace_markdown(section: dict[str, Any]) -> list[str]:
    """report.md lines of the "workspace" dict."""
    corners = section["corners"]
    names = list(corners[0]["beam_MPa"])
    refined = "fem_refined_MPa" in corners[0]
    lines = ["## Workspace corners", "",
             "Peak von Mises stress [MPa] per chain at the eight corners of the workspace (angles from the "
             "zero-command pose, reached on the prototype); beam bound / FEM" + (" / FEM refined" if refined else "")
             + ".", "",
             "| corner [mrad] | commands [mm] | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for row in corners:
        cells = []
        for n in names:
            parts = [_cell(row["beam_MPa"], n), _cell(row["fem_MPa"], n)]
            if refined:
                parts.append(_cell(row["fem_refined_MPa"], n))
            cells.append(" / ".join(parts))
        lines.append(f"| {', '.join(f'{v:+g}' for v in row['angles_mrad'])} | "
                     f"{', '.join(f'{v:+.3f}' for v in row['commands_mm'])} | " + " | ".join(cells) + " |")
    lines += ["", "Safety against yield at the corners: "
              + ", ".join(f"{n} {v:.2f}" for n, v in section["safety_factor_at_corners"].items()) + ".", ""]
    worst = max(range(len(corners)), key=lambda i: max((corners[i]["fem_MPa"] or corners[i]["beam_MPa"]).values()))
    where = corners[worst]["fem_where"] or corners[worst]["beam_where"]
    lines += [f"Where, at the most stressed corner ({', '.join(f'{v:+g}' for v in corners[worst]['angles_mrad'])} "
              "mrad):", ""] + [f"* {n}: {w}" for n, w in where.items()] + [""]
    if "trajectory" in section:
        lines += ["## Along the standard trajectory", "", "| chain | source | peak [MPa] | point | where |",
                  "|---|---|---|---|---|"]
        for source, entry in section["trajectory"].items():
            if entry is None:
                continue
            for n in names:
                lines.append(f"| {n} | {source} | {_cell(entry['MPa'], n)} | {entry['point'][n]} | {entry['where'][n]} |")
        lines.append("")
    if "support_stiffness" in section:
        k = section["support_stiffness"]
        lines += ["## Support stiffness over the corners", "",
                  "| | x | y | z | rx | ry | rz |", "|---|---|---|---|---|---|---|",
                  "| nominal | " + " | ".join(f"{v:.3g}" for v in k["nominal_diagonal"]) + " |",
                  "| min over corners | " + " | ".join(f"{v:.3g}" for v in k["min_over_corners"]) + " |",
                  "| max over corners | " + " | ".join(f"{v:.3g}" for v in k["max_over_corners"]) + " |",
                  f"| worst corner {k['worst_corner'] + 1} / nominal | "
                  + " | ".join(f"{v:.3f}" for v in k["worst_corner_ratio"]) + " |", ""]
    s = section["stroke_limit_mm"]
    lines += ["## Stress-limited stroke [mm]", "", s["what"] + f"; design safety factor {s['design_safety_factor']:g} "
              "(docs/structure.md says why).", "", "| limit | actuator | + | - |", "|---|---|---|---|"]
    for label, table in s.items():
        if isinstance(table, dict):
            for actuator, both in table.items():
                lines.append(f"| {label} | {actuator} | {both['+']:.3f} | {both['-']:.3f} |")
    return lines + [""]
