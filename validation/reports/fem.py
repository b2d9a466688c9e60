"""FEM against closed form for one hinge or one chain: the computation behind
``flexcal hinge`` and ``flexcal chain``, and their report files.

Both compare a 6 x 6 compliance at the free reference point (the hinge's free end face;
the chain's end B with end A clamped) entry by entry: FEM (quadratic tets, condensed)
against the analytic formulas of ``flexcal.model`` (Euler-Bernoulli integrals, Timoshenko
beams, Eq. 1 serial composition). DOF order ux, uy, uz, rx, ry, rz; SI.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from flexcal.geometry.params import STEEL, FlexureChain, Material
from flexcal.geometry.profiles import HingeProfile

__all__ = ["ComparisonResult", "compare_hinge", "compare_chain", "percent_difference", "write_comparison"]

DOF = ("ux", "uy", "uz", "rx", "ry", "rz")
LOAD = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
# An entry is compared when its analytic magnitude is at least this fraction of the
# geometric mean of its row's and column's diagonal terms (a unit-free measure of
# coupling); smaller entries are zero by symmetry in beam theory and FEM round-off there
# carries no meaning as a percentage.
DOMINANT_FRACTION = 1e-3


def percent_difference(fem: np.ndarray, analytic: np.ndarray) -> np.ndarray:
    """100 (fem - analytic) / analytic for the dominant entries, NaN elsewhere (6, 6)."""
    scale = np.sqrt(np.outer(np.abs(np.diag(analytic)), np.abs(np.diag(analytic))))
    dominant = np.abs(analytic) >= DOMINANT_FRACTION * scale
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(dominant, 100.0 * (fem - analytic) / analytic, np.nan)


@dataclass(frozen=True, kw_only=True, eq=False)
class ComparisonResult:
    """kind "hinge" or "chain"; params; compliance_fem / compliance_analytic (6, 6) [SI];
    stiffness_fem / stiffness_analytic (12, 12) for chains; mesh (TetMesh), mesh_report;
    displacement (n_nodes, 3) [m] of the picture's load case and its description;
    timings [s]."""

    kind: str
    params: Any
    material: Material
    compliance_fem: np.ndarray
    compliance_analytic: np.ndarray
    stiffness_fem: np.ndarray | None
    stiffness_analytic: np.ndarray | None
    mesh: Any
    mesh_report: Any
    displacement: np.ndarray
    load_case: str
    timings: dict[str, float]


MESHERS = ("mapped", "tetwild")


def _mesh(part, elements_through_thickness: float, mesher: str):
    """(mesh, report) of ``part`` by the mapped mesher (deterministic: hinges, chains and
    chain segments) or fTetWild (any part; repeatable only with the compiled seed)."""
    if mesher == "mapped":
        from flexcal.fem.mesh_mapped import mapped_mesh_part
        from flexcal.fem.mesh_mapped_chain import chain_mapped_supported, mapped_mesh_chain

        if chain_mapped_supported(part.params):
            return mapped_mesh_chain(part.params, elements_through_thickness=elements_through_thickness)
        return mapped_mesh_part(part, elements_through_thickness=elements_through_thickness)
    if mesher != "tetwild":
        raise ValueError(f"mesher={mesher!r} must be one of {', '.join(MESHERS)}")
    from flexcal.fem.mesh import mesh_part

    return mesh_part(part, elements_through_thickness=elements_through_thickness)


def _no_stage(name: str) -> None:
    return None


def _report_to_json(report) -> str:
    from dataclasses import asdict

    return json.dumps(asdict(report), sort_keys=True)


def _report_from_json(text: str):
    from flexcal.fem.mesh import MeshReport, NeckReport

    fields = json.loads(text)
    fields["necks"] = tuple(NeckReport(**neck) for neck in fields["necks"])
    fields["retry_reasons"] = tuple(fields["retry_reasons"])
    return MeshReport(**fields)


def _solve_cached(kind: str, params, material: Material, elements_through_thickness: float, mesher: str,
                  cache: bool, solve: Callable[[Any], dict[str, np.ndarray]], build, stage):
    """The FEM half of a comparison: CAD solid, mesh, ``solve(part, mesh)`` -> arrays;
    through the FEM cache (``flexcal.fem.cache``) when ``cache``. Returns (mesh, mesh
    report, arrays, timings); on a cache hit the timings hold only "cache"."""
    from flexcal.fem.cache import cached
    from flexcal.fem.mesh import TetMesh

    timings: dict[str, float] = {}

    def compute() -> dict[str, np.ndarray]:
        stage("CadQuery solid")
        start = time.perf_counter()
        part = build(params)
        timings["geometry"] = time.perf_counter() - start
        stage(f"{mesher} mesh")
        start = time.perf_counter()
        mesh, report = _mesh(part, elements_through_thickness, mesher)
        timings["mesh"] = time.perf_counter() - start
        stage("FEM solve + condensation")
        start = time.perf_counter()
        arrays = solve(part, mesh)
        timings["fem_solve"] = time.perf_counter() - start
        return {"nodes": mesh.nodes, "tets": mesh.tets, "mesh_report": np.array(_report_to_json(report)), **arrays}

    start = time.perf_counter()
    if cache:
        parts = {"kind": f"flexcal {kind} comparison", "params": params, "material": material,
                 "mesh": {"mesher": mesher, "elements_through_thickness": float(elements_through_thickness)}}
        arrays = cached(parts, compute)
    else:
        arrays = compute()
    if not timings:  # served by the cache
        for name in ("CadQuery solid", f"{mesher} mesh", "FEM solve + condensation"):
            stage(name)
        timings["cache"] = time.perf_counter() - start
    mesh = TetMesh(np.asarray(arrays["nodes"], float), np.asarray(arrays["tets"], np.int64))
    report = _report_from_json(str(arrays["mesh_report"]))
    return mesh, report, arrays, timings


def compare_hinge(hinge: HingeProfile, material: Material = STEEL, *,
                  elements_through_thickness: float = 3, stage: Callable[[str], None] = _no_stage,
                  mesher: str = "tetwild", cache: bool = False) -> ComparisonResult:
    """FEM and closed-form 6 x 6 compliance of a hinge at its free end; ``stage(name)`` is
    called as each stage starts (progress display). ``mesher`` "mapped" (deterministic:
    the same mesh and numbers on every run) or "tetwild"; ``cache`` stores mesh and
    results in the FEM cache (``flexcal.fem.cache``) and serves them from it."""
    from flexcal.fem.condense import hinge_displacement, solve_hinge
    from flexcal.geometry.solids import hinge_solid
    from flexcal.model.chain import hinge_part_compliance

    moment = 1.0  # [N m] about z: the hinge's working rotation; the picture scales it anyway

    def solve(part, mesh) -> dict[str, np.ndarray]:
        solution = solve_hinge(mesh, material, part.end_planes["fixed"], part.end_planes["free"],
                               part.reference_points["free"])
        return {"compliance": solution.compliance,
                "displacement": hinge_displacement(solution, np.array([0, 0, 0, 0, 0, moment]))}

    mesh, report, arrays, timings = _solve_cached("hinge", hinge, material, elements_through_thickness, mesher,
                                                  cache, solve, hinge_solid, stage)
    analytic = hinge_part_compliance(hinge, material)  # blocks elastic, like the FEM part
    return ComparisonResult(kind="hinge", params=hinge, material=material, compliance_fem=arrays["compliance"],
                            compliance_analytic=analytic, stiffness_fem=None, stiffness_analytic=None, mesh=mesh,
                            mesh_report=report, displacement=arrays["displacement"],
                            load_case="moment Mz = 1 N m at the free end", timings=timings)


def _clamped_a_compliance(stiffness_12: np.ndarray) -> np.ndarray:
    """6 x 6 compliance at B with A clamped, from a 12 x 12 (A then B)."""
    return np.linalg.inv(stiffness_12[6:, 6:])


def compare_chain(chain: FlexureChain, material: Material = STEEL, *,
                  elements_through_thickness: float = 6, stage: Callable[[str], None] = _no_stage,
                  mesher: str = "mapped", cache: bool = False) -> ComparisonResult:
    """FEM and analytic (Eq. 1) stiffness of a chain between its end faces A and B;
    ``stage(name)``, ``mesher`` and ``cache`` as in ``compare_hinge`` (the mapped mesher:
    ``flexcal.fem.mesh_mapped_chain``)."""
    from flexcal.fem.condense import chain_displacement, solve_chain
    from flexcal.geometry.solids import chain_solid
    from flexcal.model.chain import chain_stiffness_matrix

    def solve(part, mesh) -> dict[str, np.ndarray]:
        solution = solve_chain(mesh, material, part.end_planes["A"], part.reference_points["A"],
                               part.end_planes["B"], part.reference_points["B"])
        stiffness = 0.5 * (solution.stiffness + solution.stiffness.T)
        # picture: A clamped, end B moved 0.1 mm sideways (local y) with its rotation free
        compliance = _clamped_a_compliance(stiffness)
        wrench = np.linalg.solve(compliance, np.array([0, 1e-4, 0, 0, 0, 0]))
        wrench[3:] = 0.0
        motion_b = compliance @ wrench
        return {"stiffness": stiffness,
                "displacement": chain_displacement(solution, np.concatenate([np.zeros(6), motion_b]))}

    mesh, report, arrays, timings = _solve_cached("chain", chain, material, elements_through_thickness, mesher,
                                                  cache, solve, chain_solid, stage)
    stiffness_fem = arrays["stiffness"]
    stiffness_analytic = chain_stiffness_matrix(chain, material)
    return ComparisonResult(kind="chain", params=chain, material=material,
                            compliance_fem=_clamped_a_compliance(stiffness_fem),
                            compliance_analytic=_clamped_a_compliance(stiffness_analytic),
                            stiffness_fem=stiffness_fem, stiffness_analytic=stiffness_analytic, mesh=mesh,
                            mesh_report=report, displacement=arrays["displacement"],
                            load_case="end A clamped, lateral force Fy at B", timings=timings)


def _matrix_table(matrix: np.ndarray, fmt: str) -> list[str]:
    lines = ["| | " + " | ".join(LOAD) + " |", "|---|" + "---:|" * 6]
    for i, row in enumerate(matrix):
        cells = ["—" if not np.isfinite(v) else format(v, fmt) for v in row]
        lines.append(f"| {DOF[i]} | " + " | ".join(cells) + " |")
    return lines


def report_data(result: ComparisonResult, params_mm: dict[str, float]) -> dict[str, Any]:
    """The report.json content (every figure, SI, matrices as nested lists)."""
    from dataclasses import asdict

    diff = percent_difference(result.compliance_fem, result.compliance_analytic)
    mesh_report = asdict(result.mesh_report)
    mesh_timings = mesh_report.pop("timings")  # wall/CPU seconds: under timings_s, to timings.json
    data: dict[str, Any] = {
        "kind": result.kind,
        "parameters_mm": params_mm,
        "material": asdict(result.material),
        "dof_order": list(DOF),
        "reference_point": "free end face centre" if result.kind == "hinge" else "end B face centre, end A clamped",
        "compliance_fem": result.compliance_fem,
        "compliance_analytic": result.compliance_analytic,
        "percent_difference": [[None if not np.isfinite(v) else float(v) for v in row] for row in diff],
        "max_abs_percent_difference_diagonal": float(np.nanmax(np.abs(np.diag(diff)))),
        "mesh": {"n_nodes": result.mesh.nodes.shape[0], "n_tets": result.mesh.tets.shape[0],
                 "n_dof": 3 * result.mesh.nodes.shape[0], "quality": mesh_report},
        "timings_s": {**result.timings, "mesh_stages": mesh_timings},
        "analytic_source": "flexcal.model (Euler-Bernoulli profile integrals, Timoshenko beams, Eq. 1); docs/model.md",
    }
    if result.kind == "hinge":
        from flexcal.model.hinge import closed_form_range_warnings

        data["closed_form_range"] = closed_form_range_warnings(result.params)
    if result.stiffness_fem is not None:
        data["stiffness_fem"] = result.stiffness_fem
        data["stiffness_analytic"] = result.stiffness_analytic
    return data


def write_comparison(result: ComparisonResult, directory: Path, params_mm: dict[str, float]) -> dict[str, Any]:
    """Write report.json (results), timings.json (wall/CPU seconds), report.md, <kind>.vtu,
    <kind>.png and <kind>-mesh.png into ``directory``."""
    from flexcal.fem.results import render_deformed_png, render_mesh_png, write_vtu

    from ..output import write_report

    data = report_data(result, params_mm)
    write_report(directory, data)
    diff = percent_difference(result.compliance_fem, result.compliance_analytic)
    title = "Flexure hinge" if result.kind == "hinge" else "Flexure chain"
    lines = [f"# {title}: FEM against closed form", "",
             "Parameters [mm]: " + ", ".join(f"{k} = {v:g}" for k, v in params_mm.items()), "",
             f"Compliance at the {data['reference_point']} (rows: displacement, columns: load; SI).", "",
             "## FEM (quadratic tets)", "", *_matrix_table(result.compliance_fem, ".4e"), "",
             "## Closed form", "", *_matrix_table(result.compliance_analytic, ".4e"), "",
             "## Difference FEM vs closed form [%] (dominant entries)", "", *_matrix_table(diff, "+.2f"), "",
             f"Mesh: {data['mesh']['n_nodes']} nodes, {data['mesh']['n_tets']} quadratic tets, "
             f"radius ratio min {result.mesh_report.radius_ratio_min:.3f} / median "
             f"{result.mesh_report.radius_ratio_median:.3f}, volume error {result.mesh_report.volume_error:+.2e}.", "",
             "Timings: timings.json (kept out of this page and of report.json so that a rerun writes the same "
             "bytes).", "",
             f"Deformed shape ({result.load_case}), coloured by von Mises stress:", "",
             f"![deformed shape]({result.kind}.png)", "", "Mesh:", "", f"![mesh]({result.kind}-mesh.png)", "",
             f"Fields (displacement, stress, von Mises) in {result.kind}.vtu for ParaView."]
    if data.get("closed_form_range"):
        lines += ["", "## Where the closed form leaves its range", "",
                  *[f"- {text}" for text in data["closed_form_range"]]]
    (directory / "report.md").write_text("\n".join(lines) + "\n")
    write_vtu(result.mesh, directory / f"{result.kind}.vtu", result.displacement, result.material)
    render_deformed_png(result.mesh, result.displacement, directory / f"{result.kind}.png", material=result.material)
    render_mesh_png(result.mesh, directory / f"{result.kind}-mesh.png")
    return data


def run_comparison(compare: Callable[..., ComparisonResult], part, params_mm: dict[str, float], out: str, *,
                   elements_through_thickness: float, progress: bool,
                   replace: bool = False, **options: Any) -> tuple[ComparisonResult, dict[str, Any]]:
    """``compare(part, ...)`` with a stage progress bar, then every output into ``out``
    (whole or not at all; ``replace``: --force, see ``output.staged_output``). Returns
    (result, report data); ``options`` go to ``compare`` (``mesher``, ``cache``). Shared by
    ``flexcal hinge`` and ``flexcal chain``."""
    from ..progress import progress_bar, stage_advancer
    from ..output import staged_output

    with progress_bar(4, type(part).__name__, enabled=progress, unit="stage") as bar:
        stage = stage_advancer(bar)
        result = compare(part, elements_through_thickness=elements_through_thickness, stage=stage, **options)
        stage("VTU, pictures, report")
        with staged_output(out, replace=replace) as staging:
            data = write_comparison(result, staging, params_mm)
        bar.update(1)
    return result, data

