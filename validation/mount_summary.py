"""What a mount does under its payload, before any measurement: the figures ``flexcal mount
FILE`` prints and writes into report.json.

On the virtual prototype with closed-form segments (``prototype.segments.analytic_provider``,
seconds, no FEM) at the nominal dimensions:

- each chain's axial load under the payload's weight at zero inputs [N], tension positive,
  the state ``flexcal structure`` reports as ``axial_load_N`` (``structure.mount.nominal_state``:
  nuts at their initial positions, no clearance);
- along the standard trajectory (``model.trajectory.standard_trajectory``) with every drive's
  clearance at the top of its error range (``[actuators] clearance_mm``, hysteresis 1, initial
  position 0): the paper's state class of each point (S1 all drives compressed, S2 a drive in
  its clearance, S3 mixed tension/compression without a gap; ``prototype.transmission.point_class``)
  and, per drive, at how many points its nut is off its compression flank (in its clearance).

The geometry figures (remote centre, chain lengths, the stroke each actuator needs, the
weakest held direction) come from ``mount_checks``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flexcal.geometry.params import MechanismParams

__all__ = ["MountSummary", "mount_summary", "summary_lines", "summary_report"]

CLASSES = ("S1", "S2", "S3")


@dataclass(frozen=True, kw_only=True, eq=False)
class MountSummary:
    """remote_centre (3,) [m] and centre_miss [m] of L1-L3's axes; chain_lengths (6,) [m];
    constraint: weakest held direction over the strongest [-]; travel (3,) [m] each
    actuator needs; axial_loads (6,) [N] at zero inputs, tension positive, L1..D3;
    clearance [m] each drive had along the trajectory; n_points; point_class (n,) "S1",
    "S2", "S3"; off_flank (n, 3) bool: drive D1..D3 in its clearance at each point;
    drive_loads (n, 3) [N] along the trajectory."""

    mechanism: MechanismParams
    remote_centre: np.ndarray
    centre_miss: float
    chain_lengths: np.ndarray
    constraint: float
    travel: np.ndarray
    axial_loads: np.ndarray
    clearance: float
    point_class: np.ndarray
    off_flank: np.ndarray
    drive_loads: np.ndarray

    @property
    def class_counts(self) -> dict[str, int]:
        return {name: int(np.sum(self.point_class == name)) for name in CLASSES}

    @property
    def drives_in_clearance(self) -> dict[str, int]:
        """{drive name: points of the trajectory where it is in its clearance}."""
        names = [p.name for p in self.mechanism.driving_chains]
        return dict(zip(names, (int(n) for n in self.off_flank.sum(axis=0))))


def mount_summary(mechanism: MechanismParams) -> MountSummary:
    """The summary of ``mechanism`` (module docstring); ~1-3 s of CPU."""
    from flexcal.model.trajectory import standard_trajectory

    from .mount_checks import free_twist, remote_centre, required_travel
    from .prototype.mechanism import build_prototype, simulate
    from .prototype.segments import analytic_provider
    from .prototype.transmission import ActuatorTransmission
    from .structure.mount import nominal_state

    provider = analytic_provider()
    at_rest = build_prototype(mechanism, [ActuatorTransmission()] * 3, provider)
    loads = nominal_state(at_rest).tension
    clearance = float(mechanism.errors.clearance[1])
    loose = build_prototype(mechanism, [ActuatorTransmission(clearance=clearance)] * 3, provider)
    run = simulate(loose, standard_trajectory(mechanism).inputs)
    centre, miss = remote_centre(mechanism)
    return MountSummary(mechanism=mechanism, remote_centre=centre, centre_miss=miss,
                        chain_lengths=np.array([p.chain.length for p in mechanism.chains]),
                        constraint=free_twist(mechanism)[0], travel=required_travel(mechanism),
                        axial_loads=np.asarray(loads, float), clearance=clearance,
                        point_class=np.asarray(run.point_class), off_flank=np.asarray(run.nut_offsets) > 0.0,
                        drive_loads=np.asarray(run.axial_loads)[:, 3:])


def _mm(values) -> str:
    return ", ".join(f"{v * 1e3:.3f}" for v in values)


def summary_lines(summary: MountSummary) -> list[str]:
    """The summary as indented lines for the terminal."""
    m = summary.mechanism
    names = [p.name for p in m.chains]
    placed = m.payload_box_centre
    counts = summary.class_counts
    in_clearance = [f"{name} at {n}" for name, n in summary.drives_in_clearance.items() if n]
    lines = [
        f"  remote centre of L1-L3: ({_mm(summary.remote_centre)}) mm, axes within {summary.centre_miss * 1e3:.3g} mm of it",
        "  chain lengths [mm]: " + ", ".join(f"{n} {v * 1e3:.1f}" for n, v in zip(names, summary.chain_lengths)),
        "  no two chains' solids overlap" + (
            f", nor a chain and the payload box centred at ({', '.join(f'{v * 1e3:g}' for v in placed)}) mm"
            if placed else "; the payload box is not placed ([payload] box_centre_mm), so not checked"),
        f"  held in every direction by the chains' axes (weakest {summary.constraint:.3g} of the strongest)",
        f"  actuator travel needed [mm]: {', '.join(f'{v * 1e3:.3g}' for v in summary.travel)} of +-"
        f"{m.actuator_half_stroke * 1e3:g} (workspace corners + x0 and clearance ranges)",
        "  axial load at zero inputs under the payload [N, tension +]: "
        + ", ".join(f"{n} {v:+.1f}" for n, v in zip(names, summary.axial_loads)),
        f"  standard trajectory ({len(summary.point_class)} points), clearance {summary.clearance * 1e3:g} mm on "
        f"every drive: S1 {counts['S1']}, S2 {counts['S2']}, S3 {counts['S3']}; "
        + (f"in their clearance: {', '.join(in_clearance)} points" if in_clearance
           else "no drive passes through its clearance"),
    ]
    return lines


def summary_report(summary: MountSummary, *, source: str) -> dict[str, Any]:
    """The summary as report.json's data (display units in the key names)."""
    m = summary.mechanism
    names = [p.name for p in m.chains]
    return {
        "command": "flexcal mount",
        "mount": source,
        "remote_centre_mm": [float(v * 1e3) for v in summary.remote_centre],
        "remote_centre_miss_mm": summary.centre_miss * 1e3,
        "chain_length_mm": {n: float(v * 1e3) for n, v in zip(names, summary.chain_lengths)},
        "payload_box_centre_mm": None if m.payload_box_centre is None else [v * 1e3 for v in m.payload_box_centre],
        "weakest_held_direction": summary.constraint,
        "actuator_travel_needed_mm": {p.name: float(v * 1e3) for p, v in zip(m.driving_chains, summary.travel)},
        "axial_load_N": {n: float(v) for n, v in zip(names, summary.axial_loads)},
        "trajectory": {"points": int(len(summary.point_class)), "clearance_mm": summary.clearance * 1e3,
                       "class_counts": summary.class_counts, "points_in_clearance": summary.drives_in_clearance,
                       "drive_load_range_N": {p.name: [float(summary.drive_loads[:, i].min()),
                                                       float(summary.drive_loads[:, i].max())]
                                              for i, p in enumerate(m.driving_chains)}},
    }
