"""``flexcal structure``'s report: the mount's modes, support stiffness, stresses and
buckling factors (docs/structure.md says what each figure means and how far to trust it).

``structure_report(mechanism, segments=...)`` computes everything on the virtual
prototype's reduced model (``flexcal.validation.structure.mount``) with either
"analytic" segments (beam-theory stiffness, rigid-piece mass, beam stresses) or "fem"
segments (``FemSegments``: Guyan stiffness and mass of meshed segments, FEM stresses,
beam stresses alongside). ``provider`` (a name of ``prototype.providers.PROVIDERS``) builds the
prototype's stiffness from the truth's provider instead (``fem``: its chains' cuts tied
through section fields; ``fem-rigid``: tied rigidly), the masses and stress fields staying the segments'. Returns a
JSON-able dict; ``markdown(report)`` renders it.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from flexcal.geometry.params import MechanismParams

__all__ = ["structure_report", "markdown", "N_MODES"]

N_MODES = 12
AXES = ("x", "y", "z", "rx", "ry", "rz")


def _segment_masses(prototype, source) -> np.ndarray:
    from .segment_mass import analytic_segment_mass

    out = np.zeros((6, 5, 12, 12))
    for c, placement in enumerate(prototype.mechanism.chains):
        xs = prototype.section_x[c]
        for s in range(5):
            args = (placement.chain, float(xs[s]), float(xs[s + 1]))
            out[c, s] = source.mass(*args) if source is not None else analytic_segment_mass(
                *args, prototype.mechanism.material)
    return out


def structure_report(mechanism: MechanismParams, *, segments: str = "analytic", elements_through: float | None = None,
                     mesher: str = "mapped", n_modes: int = N_MODES, trajectory_points: int = 77, refine: bool = False,
                     figures=None, progress: bool = False, workers: int | None = None,
                     provider: str | None = None) -> dict[str, Any]:
    """The structural report of ``mechanism`` (module docstring); ``segments`` "analytic"
    or "fem"; ``mesher`` ("mapped" or "tetwild") and ``elements_through`` (None: the
    mesher's default, ``fem_segments.DEFAULT_ELEMENTS_THROUGH``): the FEM mesh;
    ``workers``: FEM segment build threads (``FemSegments``); ``trajectory_points``: points of the
    standard trajectory the stresses are taken over (0: nominal only); ``refine`` (FEM
    segments only): the workspace stresses of the driving chains again one mesh
    refinement finer (``fem_segments.REFINE_STEP``; ``workspace_report.REFINED_CHAINS``; same states,
    segments built or read from the cache); ``figures``: a folder
    to write mode_1.png .. mode_6.png and modes.vtu into (``mode_shapes``), or None."""
    from ..blas_threads import single_blas_thread
    from ..prototype.mechanism import build_prototype
    from ..prototype.segments import analytic_provider
    from ..prototype.transmission import ActuatorTransmission
    from .fem_segments import FemSegments, chain_peak_stress_fem
    from .mount import (chain_buckling_factors, chain_end_reduction, mount_buckling_factor, mount_mass, mount_modes, nominal_state,
                        payload_mass_matrix, support_stiffness)
    from .buckling_check import newton_buckling_scan
    from .craig_bampton import mount_reductions
    from .segment_mass import chain_mass
    from .stress import chain_peak_stress_beam

    from flexcal.model.trajectory import standard_trajectory

    from .workspace_report import workspace_section

    if segments not in ("analytic", "fem"):
        raise ValueError(f"segments={segments!r} must be 'analytic' or 'fem'")
    if refine and segments != "fem":
        raise ValueError("refine needs segments='fem' (the beam-theory stresses have no mesh to refine)")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    fem = None
    if segments == "fem":
        fem = FemSegments(mechanism.material, elements_through=elements_through, mesher=mesher, progress=progress,
                          workers=workers)
    fem_fine = fem.refined() if refine else None
    if provider is not None:
        from ..prototype.providers import stiffness_provider

        stiffness = stiffness_provider(provider, progress=progress, workers=workers)
    else:
        stiffness = fem if fem is not None else analytic_provider(mechanism.material)
    prototype = build_prototype(mechanism, [ActuatorTransmission()] * 3, stiffness)
    if fem_fine is not None:  # the refined driving chains built side by side now, not one by one later
        from ..prototype.segments import chain_slices
        from .workspace_report import REFINED_CHAINS

        fem_fine.prepare(chain_slices(mechanism.chains[c].chain for c in REFINED_CHAINS))
    seg_mass = _segment_masses(prototype, fem)
    timings["segments_s"] = time.perf_counter() - t0
    with single_blas_thread():
        t = time.perf_counter()
        loaded, unloaded = nominal_state(prototype), nominal_state(prototype, 0.0)
        timings["equilibrium_s"] = time.perf_counter() - t
        t = time.perf_counter()
        M = mount_mass(prototype, seg_mass, payload_mass_matrix(mechanism))
        modes = mount_modes(prototype, loaded, M, n_modes)
        # the same mass on the unloaded tangent: no stress stiffening by the payload's weight
        unstiffened = mount_modes(prototype, unloaded, M, n_modes)
        figure_names = []
        if figures is not None:
            from pathlib import Path

            from .mode_shapes import write_mode_pngs, write_modes_vtu

            figure_names = write_mode_pngs(Path(figures), prototype, loaded.poses, modes.modes, modes.frequencies)
            write_modes_vtu(Path(figures) / "modes.vtu", prototype, loaded.poses, modes.modes, modes.frequencies)
            figure_names.append("modes.vtu")
        reductions = mount_reductions(prototype, loaded.tangent, M)
        timings["modes_s"] = time.perf_counter() - t
        t = time.perf_counter()
        k_held = support_stiffness(prototype, loaded.tangent)
        k_springs = support_stiffness(prototype, loaded.tangent, nuts_held=False)
        timings["support_stiffness_s"] = time.perf_counter() - t
        t = time.perf_counter()
        factor = mount_buckling_factor(unloaded, loaded)
        chains = chain_buckling_factors(prototype, loaded)
        scan = newton_buckling_scan(prototype)
        timings["buckling_s"] = time.perf_counter() - t
        t = time.perf_counter()
        beam_nominal = chain_peak_stress_beam(prototype, loaded.segment_gradient)
        fem_nominal = chain_peak_stress_fem(prototype, loaded.poses, fem) if fem is not None else None
        commands = standard_trajectory(mechanism, n_points=trajectory_points).inputs if trajectory_points else None
        workspace = workspace_section(prototype, fem=fem, fem_fine=fem_fine, trajectory_commands=commands,
                                      nominal_stiffness=k_held)
        if commands is not None:
            path = workspace["trajectory"]
            beam_path = np.array([path["beam"]["MPa"][c.name] for c in mechanism.chains]) * 1e6
            fem_path = None if fem is None else np.array([path["fem"]["MPa"][c.name] for c in mechanism.chains]) * 1e6
        timings["stress_workspace_s"] = time.perf_counter() - t
    yield_strength = mechanism.material.yield_strength
    names = [c.name for c in mechanism.chains]

    def per_chain(values):
        return None if values is None else {n: float(v) for n, v in zip(names, values)}

    def mpa(values):
        return None if values is None else {n: float(v) / 1e6 for n, v in zip(names, values)}

    stress: dict[str, Any] = {
        "yield_strength_MPa": yield_strength / 1e6,
        "nominal_beam_MPa": mpa(beam_nominal), "nominal_fem_MPa": mpa(fem_nominal),
    }
    governing = fem_nominal if fem_nominal is not None else beam_nominal
    if commands is not None:
        stress.update({"trajectory_points": int(len(commands)), "trajectory_beam_MPa": mpa(beam_path),
                       "trajectory_fem_MPa": mpa(fem_path)})
        governing = np.maximum(governing, fem_path if fem_path is not None else beam_path)
    stress["safety_factor_against_yield"] = per_chain(yield_strength / governing)
    total_modal = modes.effective_mass.sum(axis=0)
    report = {
        "command": "flexcal structure",
        "segments": segments,
        "provider": prototype.provider_description,
        "material": dataclasses.asdict(mechanism.material),
        "payload": {"mass_kg": mechanism.payload_mass, "box_mm": [1e3 * s for s in mechanism.payload_box],
                    "centre_of_gravity_mm": [1e3 * v for v in mechanism.centre_of_gravity]},
        "chain_mass_kg": {c.name: chain_mass(c.chain, mechanism.material) for c in mechanism.chains},
        "chain_guyan_ends": {
            "what": "each chain Guyan-reduced onto its end nodes A, B: 12 x 12 stiffness and mass, chain axes, "
                    "DOFs ux..rz at A then B (SI)",
            **{c.name: dict(zip(("stiffness", "mass"), (m.tolist() for m in chain_end_reduction(prototype, seg_mass, i))))
               for i, c in enumerate(mechanism.chains)}},
        "axial_load_N": per_chain(loaded.tension),
        "modes": {
            "frequencies_Hz": modes.frequencies.tolist(),
            "frequencies_without_preload_Hz": unstiffened.frequencies.tolist(),
            "preload": "frequencies_Hz: tangent at the nominal state (the payload's weight, geometric stiffness "
                       "included); without_preload: the unloaded tangent, same mass",
            "figures": figure_names,
            "effective_mass": [dict(zip(AXES, row)) for row in modes.effective_mass.tolist()],
            "effective_mass_units": "kg for x, y, z; kg m^2 for rx, ry, rz (about O_C)",
            "captured_fraction": dict(zip(AXES, (total_modal / modes.total_mass).tolist())),
            "total_moving_mass": dict(zip(AXES, modes.total_mass.tolist())),
        },
        "craig_bampton": {
            "what": "mount frequencies [Hz] with the chains' interior DOFs condensed statically (guyan) or with n "
                    "fixed-interface modes kept (craig_bampton_n), against all DOFs (full); fixed_interface_Hz: "
                    "each chain's own lowest modes, payload frame and nuts held",
            **reductions},
        "support_stiffness": {
            "point": "O_C, frame (mechanism) axes; DOFs ux, uy, uz [m], rx, ry, rz [rad]",
            "units": "N/m, N/rad (= N m/m), N m/rad",
            "nuts_held": k_held.tolist(),
            "nuts_on_actuator_springs": k_springs.tolist(),
            "diagonal_nuts_held": dict(zip(AXES, np.diag(k_held).tolist())),
        },
        "stress": stress,
        "workspace": workspace,
        "buckling": {
            "mount_weight_factor": factor,
            "chain_held": per_chain(chains["held"]),
            "chain_sway": per_chain(chains["sway"]),
            "newton_scan": {"what": "Newton at increasing weight factors; lowest_eigenvalue mu of K_T(s) phi = mu K_0 "
                                    "phi (linearized: 1 - s / factor)", **scan},
            "note": "factors on the nominal load; inf (null in JSON) for a chain in tension",
        },
        "timings_s": {**timings, "total_s": time.perf_counter() - t0},
    }
    return report




def _fmt(value, digits: int = 3) -> str:
    if value is None:
        return "-"
    if not np.isfinite(value):
        return "inf"
    return f"{value:.{digits}g}"


def markdown(report: dict[str, Any]) -> str:
    """report.md: the figures of ``structure_report`` as tables."""
    lines = ["# Mount structure (`flexcal structure`)", "",
             f"Segments: {report['segments']} ({report['provider']}). Payload {report['payload']['mass_kg']:g} kg "
             f"filling a {' x '.join(f'{v:g}' for v in report['payload']['box_mm'])} mm box, centre of gravity "
             f"{report['payload']['centre_of_gravity_mm']} mm. What each figure means and how far to trust it: "
             "docs/structure.md.", "", "## Modes", "",
             "| mode | f [Hz] | f without preload [Hz] | " + " | ".join(f"m_eff {a}" for a in AXES) + " |",
             "|---|---|---|" + "---|" * len(AXES)]
    for k, (f, f0, row) in enumerate(zip(report["modes"]["frequencies_Hz"],
                                         report["modes"]["frequencies_without_preload_Hz"],
                                         report["modes"]["effective_mass"]), 1):
        lines.append(f"| {k} | {f:.2f} | {f0:.2f} | " + " | ".join(_fmt(row[a]) for a in AXES) + " |")
    captured = report["modes"]["captured_fraction"]
    lines += ["", "Effective mass in kg (x, y, z) and kg m^2 (rx, ry, rz about O_C); the modes shown capture "
              + ", ".join(f"{a} {100 * captured[a]:.0f} %" for a in AXES) + " of the moving mass.", "",
              "Without preload: the unloaded tangent (no stress stiffening by the payload's weight), same mass. "
              + (f"Shapes: {', '.join(report['modes']['figures'])}." if report["modes"].get("figures") else ""), "",
              "## Support stiffness at O_C (nuts held)", "",
              "| | " + " | ".join(AXES) + " |", "|---|" + "---|" * 6]
    for a, row in zip(AXES, report["support_stiffness"]["nuts_held"]):
        lines.append(f"| {a} | " + " | ".join(f"{v:.3g}" for v in row) + " |")
    lines += ["", "Units: N/m, N/rad, N m/rad (rows: displacement DOF, columns: load).", "",
              "## Stress and buckling per chain", "",
              f"Yield strength {report['stress']['yield_strength_MPa']:g} MPa (`Material.yield_strength`; default: "
              "S355J2, EN 10025-2, R_eH for 40-63 mm products). Stresses: beam-theory bound at the leaves' thin "
              "ends and, with FEM segments, the largest nodal von Mises stress; nominal = design commands, "
              f"trajectory = the largest over the standard trajectory's {report['stress'].get('trajectory_points', 0)} "
              "points. Buckling factors multiply the loads each chain carries at the nominal state.", "",
              "| chain | axial load [N] | nominal beam [MPa] | nominal FEM [MPa] | trajectory beam [MPa] | "
              "trajectory FEM [MPa] | safety vs yield | buckling held | buckling sway |",
              "|---|---|---|---|---|---|---|---|---|"]
    s, b = report["stress"], report["buckling"]
    for name in report["axial_load_N"]:
        def get(table):
            return None if table is None else table[name]
        lines.append(f"| {name} | {report['axial_load_N'][name]:.0f} | {_fmt(get(s['nominal_beam_MPa']))} | "
                     f"{_fmt(get(s['nominal_fem_MPa']))} | {_fmt(get(s.get('trajectory_beam_MPa')))} | "
                     f"{_fmt(get(s.get('trajectory_fem_MPa')))} | {_fmt(get(s['safety_factor_against_yield']))} | "
                     f"{_fmt(get(b['chain_held']))} | {_fmt(get(b['chain_sway']))} |")
    if "workspace" in report:
        from .workspace_report import workspace_markdown

        lines += [""] + workspace_markdown(report["workspace"])
    scan = b["newton_scan"]
    lines += ["", f"Mount buckling: the payload's weight x **{b['mount_weight_factor']:.3g}** makes the mount's "
              "tangent singular (linearized about the unloaded state). Newton's check: the lowest eigenvalue of "
              "K_T(s) against K_0 falls " + ", ".join(f"{m:.3f} at {f:g}" for f, m in
                                                      zip(scan["factors"], scan["lowest_eigenvalue"]))
              + f"; Newton converges up to x {_fmt(scan['newton_converged_to'])}, fails at x "
              f"{_fmt(scan['newton_failed_at'])}; the eigenvalue reaches 0 at x {_fmt(scan['zero_crossing'])}.", "",
              "## Chains: Craig-Bampton against Guyan", "",
              "Each chain's own lowest modes (payload frame and nuts held) [Hz]: "
              + "; ".join(f"{n} " + ", ".join(f"{v:.0f}" for v in f) for n, f in
                          report["craig_bampton"]["fixed_interface_Hz"].items()) + ".", "",
              "| model | " + " | ".join(str(k) for k in range(1, 13)) + " |", "|---|" + "---|" * 12]
    for name, freqs in report["craig_bampton"].items():
        if isinstance(freqs, list):
            lines.append(f"| {name} | " + " | ".join(f"{v:.1f}" for v in freqs) + " |" + " - |" * (12 - len(freqs)))
    lines += ["",
              "Wall times [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in report["timings_s"].items()), ""]
    return "\n".join(lines)
