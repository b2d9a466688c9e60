"""flexcal.fem: tet meshes (pytetwild), quadratic-tet linear elasticity, rigid coupling, condensation, cache, VTU.

Public names are imported on first use (PEP 562), so importing the package stays
cheap and never pulls in a heavy dependency a caller does not need.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "TetMesh": "mesh",
    "MeshReport": "mesh",
    "NeckReport": "mesh",
    "mesh_part": "mesh",
    "snap_to_part": "mesh",
    "linear_to_quadratic": "mesh",
    "HingeSolution": "condense",
    "ChainSolution": "condense",
    "solve_hinge": "condense",
    "hinge_compliance": "condense",
    "hinge_displacement": "condense",
    "solve_chain": "condense",
    "chain_stiffness": "condense",
    "chain_displacement": "condense",
    "twist_transform": "condense",
    "check_mesh": "assembly",
    "element_dofs": "assembly",
    "node_pattern": "assembly",
    "assemble_stiffness": "assembly",
    "assemble_body_force": "assembly",
    "n_dofs": "assembly",
    "EDGES": "elements",
    "REFERENCE_NODES": "elements",
    "InvalidElementError": "elements",
    "QuadratureRule": "elements",
    "TET_4POINT": "elements",
    "TET_14POINT": "elements",
    "shape_functions": "elements",
    "shape_gradients": "elements",
    "elasticity_matrix": "elements",
    "lame_parameters": "elements",
    "strain_displacement": "elements",
    "jacobians": "elements",
    "affine_elements": "elements",
    "element_stiffness": "elements",
    "element_stiffness_blocks": "elements",
    "element_volumes": "elements",
    "element_strain_at_nodes": "elements",
    "DEFAULT_PLANE_TOLERANCE": "coupling",
    "RigidCoupling": "coupling",
    "CouplingMap": "coupling",
    "mesh_size": "coupling",
    "select_plane_nodes": "coupling",
    "coupling_map": "coupling",
    "skew": "coupling",
    "rigid_body_modes": "coupling",
    "eliminate_dofs": "coupling",
    "SOLVERS": "solve",
    "solve_spd": "solve",
    "pardiso_available": "solve",
    "CACHE_ENV": "cache",
    "cache_dir": "cache",
    "code_version": "cache",
    "canonical": "cache",
    "cache_key": "cache",
    "load_cached": "cache",
    "store_cached": "cache",
    "cached": "cache",
    "nodal_stress": "results",
    "von_mises": "results",
    "to_pyvista": "results",
    "write_vtu": "results",
    "render_deformed_png": "results",
    "StructuredTetMesh": "structured",
    "grid_tet_mesh": "structured",
    "box_tet_mesh": "structured",
    "notch_hinge_tet_mesh": "structured",
    "notch_height": "structured",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return __all__
