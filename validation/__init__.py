"""flexcal.validation: the virtual prototype, measurement files, scenarios, reports and the flexcal command line.

Public names load on first use (``flexcal.geometry._lazy``).
"""

from __future__ import annotations

from flexcal.geometry._lazy import lazy_exports

_EXPORTS = {
    "Prototype": "prototype.mechanism",
    "PrototypeRun": "prototype.mechanism",
    "build_prototype": "prototype.mechanism",
    "apply_mount_offsets": "prototype.mechanism",
    "simulate": "prototype.mechanism",
    "FRAME_BODY": "prototype.mechanism",
    "NUT_BODIES": "prototype.mechanism",
    "as_built": "prototype.truth",
    "make_truth": "prototype.truth",
    "TruthResult": "prototype.truth",
    "Scenario": "prototype.scenario",
    "load_scenario": "prototype.scenario",
    "BUILTIN_SCENARIOS": "prototype.scenario",
    "scenario_trajectory": "prototype.scenario",
    "Measurement": "measurements",
    "REQUIRED_COLUMNS": "measurements",
    "read_measurement": "measurements",
    "write_measurement": "measurements",
    "sidecar_path": "measurements",
    "VerifySettings": "runs.verify",
    "VerifyResult": "runs.verify",
    "run_verify": "runs.verify",
    "PAPER_TABLE1": "runs.verify",
    "ComparisonResult": "reports.fem",
    "compare_hinge": "reports.fem",
    "compare_chain": "reports.fem",
    "percent_difference": "reports.fem",
    "write_comparison": "reports.fem",
    "fem_provider": "prototype.fem_provider",
    "segment_stiffness_fem": "prototype.fem_provider",
    "mirror_segment_stiffness": "prototype.fem_provider",
    "DEFAULT_ELEMENTS_THROUGH": "prototype.fem_provider",
    "StiffnessProvider": "prototype.segments",
    "section_nodes": "prototype.segments",
    "rigid_transfer": "prototype.segments",
    "expand_end_stiffness": "prototype.segments",
    "end_stiffness": "prototype.segments",
    "rigid_mode_defect": "prototype.segments",
    "end_compliance": "prototype.segments",
    "analytic_provider": "prototype.segments",
    "ActuatorTransmission": "prototype.transmission",
    "play_operator": "prototype.transmission",
    "nut_offset": "prototype.transmission",
    "point_class": "prototype.transmission",
    "DEFAULT_BREAKAWAY_FORCE": "prototype.transmission",
    "staged_output": "output",
    "write_json": "output",
    "write_report": "output",
    "to_jsonable": "output",
    "plot_misalignment_curves": "reports.plots",
    "CLASS_COLOURS": "reports.plots",
}

__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
