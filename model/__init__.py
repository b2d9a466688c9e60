"""flexcal.model: the paper's analytic model (Eq. 1-8), forward and inverse, batched; the 45 error sources.

Public names are imported on first use (PEP 562), so importing the package stays
cheap and never pulls in a heavy dependency a caller does not need.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "Parameter": "parameters",
    "ParameterSpace": "parameters",
    "parameter_space": "parameters",
    "parameter_table_markdown": "parameters",
    "DIMENSION_SYMBOLS": "parameters",
    "CHAIN_NAMES": "parameters",
    "ForwardResult": "forward",
    "forward": "forward",
    "solve_matrices": "forward",
    "ideal_pose": "forward",
    "ideal_angles": "forward",
    "ConvergenceError": "forward",
    "resolve_engine": "forward",
    "STATE_NAMES": "forward",
    "CLASS_NAMES": "forward",
    "STATE_TOLERANCE": "forward",
    "CLEARANCE_MODES": "forward",
    "ENGINES": "forward",
    "InverseResult": "inverse",
    "inverse": "inverse",
    "NotInvertibleError": "inverse",
    "forward_jacobian": "inverse",
    "Trajectory": "trajectory",
    "standard_trajectory": "trajectory",
    "travel_directions": "trajectory",
    "WORKSPACE": "trajectory",
    "MIN_MOVE": "trajectory",
    "segment_compliance": "hinge",
    "segment_entries": "hinge",
    "entries_to_matrix": "hinge",
    "ENTRY_INDEX": "hinge",
    "leaf_compliance": "hinge",
    "circular_notch_compliance": "hinge",
    "beam_compliance": "hinge",
    "hinge_compliance_matrix": "hinge",
    "profile_integrals": "hinge",
    "profile_thickness": "hinge",
    "torsion_constant": "hinge",
    "shear_coefficient": "hinge",
    "circular_notch_rotation_compliance": "hinge",
    "serial_compliance": "chain",
    "hinge_part_compliance": "chain",
    "chain_elements": "chain",
    "chain_compliance": "chain",
    "chain_compliance_matrix": "chain",
    "chain_stiffness_matrix": "chain",
    "invert_axial_compliance": "chain",
    "chain_compliance_entries": "chain",
    "stiffness_from_entries": "chain",
    "LEAF2_ROTATION": "chain",
    "MechanismMatrices": "assembly",
    "mechanism_matrices": "assembly",
    "payload_wrench": "assembly",
    "N_CHAINS": "assembly",
    "DRIVING": "assembly",
    "skew": "frames",
    "twist_transform": "frames",
    "frame_to_point_transform": "frames",
    "axis_rotation": "frames",
    "rotation_about_x": "frames",
    "read_parameter_file": "param_file",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return __all__
