"""One design of a sweep: design dict -> record dict (a pure function, run on a worker).

For a hinge (kind circular / leaf) the record holds the 6 x 6 compliance at the free end
face (fixed end clamped) from the FEM and from the closed form
(``flexcal.model.chain.hinge_part_compliance``, blocks elastic like the FEM part), the
percent discrepancy of each diagonal entry, and the peak von Mises stress per unit
rotation about z [Pa/rad]: the FEM stress field of a pure moment Mz at the free end,
scaled so the free end turns by 1 rad (linear elasticity). Beside it the beam-theory
value 6 / (b t^2 C_rz,Mz) of the closed form: nominal bending stress at the thinnest
section, no stress concentration.

For a chain (kind chain) the compliance is the one at end B with end A clamped, the
stress the one of a pure moment Mz at B (leaf 1 bending) per radian of B's rotation; and
its structural figures (``sweep.chain_structure``): first clamped frequency, peak stress
in the leaves per metre of B's sideways stroke, sway buckling load and its factor on the
design's ``axial_load_n``.

The FEM numbers go through the content-addressed cache (``flexcal.fem.cache``), so a
design solved once, by any sweep, is never meshed again.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

__all__ = ["evaluate_design", "fem_summary", "DIAGONAL"]

DIAGONAL = ("ux_Fx", "uy_Fy", "uz_Fz", "rx_Mx", "ry_My", "rz_Mz")


def _mesh(part, elements_through: float):
    from flexcal.fem.mesh import mesh_part

    # one fTetWild thread: each sweep worker is one process on one core
    return mesh_part(part, elements_through_thickness=elements_through, num_threads=1)


def _hinge_fem(hinge, material, elements_through: float) -> dict[str, np.ndarray]:
    from flexcal.fem.condense import hinge_displacement, solve_hinge
    from flexcal.fem.results import nodal_stress, von_mises
    from flexcal.geometry.solids import hinge_solid

    part = hinge_solid(hinge)
    mesh, _ = _mesh(part, elements_through)
    solution = solve_hinge(mesh, material, part.end_planes["fixed"], part.end_planes["free"],
                           part.reference_points["free"])
    u = hinge_displacement(solution, np.array([0.0, 0, 0, 0, 0, 1.0]))  # Mz = 1 N m
    peak = von_mises(nodal_stress(mesh, material, u)).max()
    return {"compliance": solution.compliance, "peak_stress_unit_moment": np.array(peak),
            "n_nodes": np.array(len(mesh.nodes))}


def _chain_fem(chain, material, elements_through: float) -> dict[str, np.ndarray]:
    from flexcal.fem.assembly import assemble_stiffness
    from flexcal.fem.condense import chain_displacement, solve_chain
    from flexcal.fem.results import nodal_stress, von_mises
    from flexcal.geometry.solids import chain_solid

    from .chain_structure import chain_structure

    part = chain_solid(chain)
    mesh, _ = _mesh(part, elements_through)
    K = assemble_stiffness(mesh, material)
    solution = solve_chain(mesh, material, part.end_planes["A"], part.reference_points["A"], part.end_planes["B"],
                           part.reference_points["B"], stiffness=K)
    stiffness = 0.5 * (solution.stiffness + solution.stiffness.T)
    compliance = np.linalg.inv(stiffness[6:, 6:])  # at B, A clamped
    motion_b = compliance @ np.array([0.0, 0, 0, 0, 0, 1.0])  # Mz = 1 N m at B
    u = chain_displacement(solution, np.concatenate([np.zeros(6), motion_b]))
    peak = von_mises(nodal_stress(mesh, material, u)).max()
    return {"compliance": compliance, "peak_stress_unit_moment": np.array(peak),
            "n_nodes": np.array(len(mesh.nodes)), **chain_structure(mesh, material, part, chain, solution, K)}


# the modules of flexcal.validation whose code computes a sweep design's FEM cache entry (its key's
# "code", as ``prototype.fem_provider.SEGMENT_CODE``)
SUMMARY_CODE = ("flexcal.validation.sweep.job", "flexcal.validation.sweep.chain_structure")


def fem_summary(params, material, elements_through: float, cache_directory=None) -> dict[str, np.ndarray]:
    """FEM compliance (6, 6) [SI], peak von Mises stress under Mz = 1 N m [Pa] and node
    count of a hinge or chain, from the cache or computed and stored."""
    from flexcal.fem.cache import cached
    from flexcal.geometry.params import FlexureChain

    solve = _chain_fem if isinstance(params, FlexureChain) else _hinge_fem
    return cached(summary_parts(params, material, elements_through), lambda: solve(params, material, elements_through),
                  cache_directory)


def summary_parts(params, material, elements_through: float) -> dict:
    """The cache key's parts of ``fem_summary``."""
    from flexcal.fem.cache import sources_digest
    from flexcal.geometry.params import FlexureChain

    # a chain's entry holds its structural figures too (sweep.chain_structure): its own kind
    return {"kind": "sweep_chain_summary" if isinstance(params, FlexureChain) else "sweep_fem_summary",
            "code": sources_digest(*SUMMARY_CODE), "part": params, "material": material,
            "mesh": {"elements_through_thickness": float(elements_through), "num_threads": 1}}


def _closed_form(params, material) -> tuple[np.ndarray, tuple[float, float]]:
    """Closed-form compliance (6, 6) and the thinnest section's (width, thickness) [m]."""
    from flexcal.geometry.params import FlexureChain
    from flexcal.model.chain import chain_stiffness_matrix, hinge_part_compliance

    if isinstance(params, FlexureChain):
        return np.linalg.inv(chain_stiffness_matrix(params, material)[6:, 6:]), (params.width, params.thickness_1)
    return hinge_part_compliance(params, material), (params.width, params.thickness)


def evaluate_design(design: dict[str, Any], *, cache_directory: str | None = None) -> dict[str, Any]:
    """The record of one design (plain JSON types): the design, FEM and closed-form
    compliance (6 x 6, SI), diagonal discrepancy [%], peak stress per unit rotation
    [Pa/rad] (FEM and beam-theory nominal), node count, wall time [s], and, when the
    design asks for it, identification accuracy (``sweep.identify``)."""
    from flexcal.geometry.params import STEEL

    from ..blas_threads import single_blas_thread
    from .space import build_part_params, design_id

    start = time.perf_counter()
    params = build_part_params(design)
    with single_blas_thread():
        fem = fem_summary(params, STEEL, design["elements_through"], cache_directory)
    c_fem = np.asarray(fem["compliance"], float)
    c_ana, (width, thickness) = _closed_form(params, STEEL)
    diff = 100.0 * (np.diag(c_fem) - np.diag(c_ana)) / np.diag(c_ana)
    record: dict[str, Any] = {
        "id": design_id(design),
        "design": design,
        "compliance_fem": c_fem.tolist(),
        "compliance_closed_form": c_ana.tolist(),
        "discrepancy_percent": dict(zip(DIAGONAL, map(float, diff))),
        # sigma / theta_z = sigma(Mz = 1) / C_rz,Mz: stresses scale linearly with the rotation
        "stress_per_rad_fem": float(fem["peak_stress_unit_moment"]) / c_fem[5, 5],
        # beam theory at the thinnest section: sigma = 6 Mz / (b t^2), theta = C Mz
        "stress_per_rad_nominal": 6.0 / (width * thickness**2 * c_ana[5, 5]),
        "n_nodes": int(fem["n_nodes"]),
    }
    if "buckling_load_sway" in fem:  # a chain (sweep.chain_structure)
        record["structure"] = {
            "first_frequency_clamped_hz": float(fem["first_frequency_clamped_hz"]),
            "stress_per_m_lateral_y": float(fem["stress_per_m_lateral"][0]),
            "stress_per_m_lateral_z": float(fem["stress_per_m_lateral"][1]),
            "buckling_load_sway_n": float(fem["buckling_load_sway"]),
            "buckling_factor": float(fem["buckling_load_sway"]) / design["axial_load_n"],
        }
    if design.get("identification", {}).get("enabled"):
        from .identify import identification_accuracy

        record["identification"] = identification_accuracy(params, design["identification"],
                                                           cache_directory=cache_directory)
    record["wall_s"] = time.perf_counter() - start
    return record
