"""flexcal.validation: the virtual prototype, measurement files, scenarios, reports and the flexcal command line.

Public names load on first use (``flexcal.geometry._lazy``).
"""

from __future__ import annotations

from flexcal.geometry._lazy import lazy_exports

_EXPORTS = {
    "Prototype": "prototype",
    "PrototypeRun": "prototype",
    "build_prototype": "prototype",
    "apply_mount_offsets": "prototype",
    "simulate": "prototype",
    "FRAME_BODY": "prototype",
    "NUT_BODIES": "prototype",
    "as_built": "truth",
    "make_truth": "truth",
    "TruthResult": "truth",
    "Scenario": "scenario",
    "load_scenario": "scenario",
    "BUILTIN_SCENARIOS": "scenario",
    "scenario_trajectory": "scenario",
    "Measurement": "measurements",
    "REQUIRED_COLUMNS": "measurements",
    "read_measurement": "measurements",
    "write_measurement": "measurements",
    "sidecar_path": "measurements",
    "VerifySettings": "verify",
    "VerifyResult": "verify",
    "run_verify": "verify",
    "PAPER_TABLE1": "verify",
    "TABLE1_NAMES": "verify",
    "ComparisonResult": "fem_report",
    "compare_hinge": "fem_report",
    "compare_chain": "fem_report",
    "percent_difference": "fem_report",
    "write_comparison": "fem_report",
    "fem_provider": "fem_provider",
    "segment_stiffness_fem": "fem_provider",
    "mirror_segment_stiffness": "fem_provider",
    "DEFAULT_ELEMENTS_THROUGH": "fem_provider",
    "StiffnessProvider": "segments",
    "section_nodes": "segments",
    "rigid_transfer": "segments",
    "expand_end_stiffness": "segments",
    "end_stiffness": "segments",
    "rigid_mode_defect": "segments",
    "end_compliance": "segments",
    "analytic_provider": "segments",
    "ActuatorTransmission": "transmission",
    "play_operator": "transmission",
    "nut_offset": "transmission",
    "point_class": "transmission",
    "DEFAULT_BREAKAWAY_FORCE": "transmission",
    "staged_output": "output",
    "write_json": "output",
    "to_jsonable": "output",
    "plot_misalignment_curves": "plots",
    "CLASS_COLOURS": "plots",
}

__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
