"""The limits of a measurement file, one definition for the reader (``measurements``) and for
every writer of one (``flexcal truth``, ``verify``'s curves.csv): what is written is read back.

An actuator input beyond 100 mm or an angle beyond 0.1 rad is not a flexure mount's
misalignment curve but a unit mistake (m vs mm, rad vs urad); the reader refuses it. The
truth command refuses up front, before the prototype runs, the sensors and trajectories
whose file the reader would refuse (``sensor_problem``, ``inputs_problem``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAX_ABS_INPUT_MM", "MAX_ABS_ANGLE_URAD", "MAX_INDEX", "NOISE_SIGMAS", "SENSOR_SHARE",
           "COLUMN_LIMITS", "first_beyond", "sensor_problem", "inputs_problem", "values_problem", "time_problem", "MAX_TIME_S", "MAX_POINTS",
           "MAX_TABLE_BYTES"]

MAX_ABS_INPUT_MM = 100.0  # [mm] |xa*_mm| above this is refused (module doc)
MAX_ABS_ANGLE_URAD = 1e5  # [urad] |theta_*_urad| above this is refused (0.1 rad, 20x the widest workspace)
MAX_INDEX = 2.0**53  # point and leg are counters: beyond 2^53 a float no longer holds every integer exactly
# Points of a curve or a trajectory (the scenario's n_points, a trajectory file's and a
# measurement's rows): the paper's curve has 77. The analytic truth takes ~30 ms a point
# here (77 points in 2.4 s), so 1e5 points are about an hour of prototype, and every model
# evaluation of an identification walks them all: more is a mistake, not a measurement.
MAX_POINTS = 100_000
# Bytes of a measurement or trajectory CSV, checked before reading: write_measurement's
# rows are ~120 bytes with one optional column; 400 a row leaves room for a dozen more.
MAX_TABLE_BYTES = 400 * MAX_POINTS
# Gaussian noise exceeds 8 sigma with probability 1.2e-15 per draw: < 1e-9 for a file of 3e5 points
NOISE_SIGMAS = 8.0
# share of the angle limit the sensor (offset + NOISE_SIGMAS x noise) may take; the rest is the
# mount's own angles (a few mrad: 5 % of the limit at most)
SENSOR_SHARE = 0.5


def sensor_problem(noise_urad, offset_urad) -> str | None:
    """Why sensors with noise (3,) and offsets (3,) [urad] would write angles the reader
    refuses, or None."""
    noise, offset = np.broadcast_to(np.asarray(noise_urad, float), (3,)), np.broadcast_to(np.asarray(offset_urad, float), (3,))
    reach = np.abs(offset) + NOISE_SIGMAS * noise
    if not np.all(np.isfinite(reach)) or np.any(reach > SENSOR_SHARE * MAX_ABS_ANGLE_URAD):
        axis = int(np.argmax(np.where(np.isfinite(reach), reach, np.inf)))
        return (f"sensor {'xyz'[axis]}: offset {offset[axis]:g} urad + {NOISE_SIGMAS:g} x noise {noise[axis]:g} urad "
                f"exceeds {SENSOR_SHARE * MAX_ABS_ANGLE_URAD:g} urad, so the file's angles would pass the reader's "
                f"limit of {MAX_ABS_ANGLE_URAD:g} urad; give a noise_urad / offset_urad below it")
    return None


# (column, limit of |value|, what the unit is): the one table of a measurement's value limits
COLUMN_LIMITS = (
    *((f"xa{i}_mm", MAX_ABS_INPUT_MM, "inputs are in mm") for i in (1, 2, 3)),
    *((f"theta_{a}_urad", MAX_ABS_ANGLE_URAD, "angles are in microradians") for a in "xyz"),
)


def first_beyond(columns: dict[str, np.ndarray]) -> tuple[int, str, str] | None:
    """(row index, column, message) of the first value of ``columns`` (name -> (n,) values in
    the file's units; the names of ``COLUMN_LIMITS`` and ``time_s`` that are present) that is
    not finite or beyond its limit, in row order, or None. The one check of the reader and of
    every writer."""
    limits = [(name, limit, unit) for name, limit, unit in COLUMN_LIMITS if name in columns]
    if "time_s" in columns:
        limits.append(("time_s", MAX_TIME_S, "time stamps are in seconds"))
    if not limits:
        return None
    values = np.column_stack([np.asarray(columns[name], dtype=float) for name, _, _ in limits])
    bad = ~np.isfinite(values) | (np.abs(values) > np.array([limit for _, limit, _ in limits]))
    if not np.any(bad):
        return None
    row, k = (int(i) for i in np.argwhere(bad)[0])
    name, limit, unit = limits[k]
    suffix = name.rsplit("_", 1)[1]
    return row, name, f"{values[row, k]:g} {suffix} exceeds the file limit of {limit:g} {suffix} ({unit})"


def _columns(inputs_mm=None, angles_urad=None) -> dict[str, np.ndarray]:
    out = {}
    if inputs_mm is not None:
        x = np.asarray(inputs_mm, dtype=float)
        out.update({f"xa{i + 1}_mm": x[:, i] for i in range(3)})
    if angles_urad is not None:
        a = np.asarray(angles_urad, dtype=float)
        out.update({f"theta_{'xyz'[i]}_urad": a[:, i] for i in range(3)})
    return out


def inputs_problem(inputs_mm) -> str | None:
    """Why trajectory inputs (n, 3) [mm] would be refused by the reader, or None."""
    beyond = first_beyond(_columns(inputs_mm=inputs_mm))
    return None if beyond is None else f"trajectory point {beyond[0] + 1}, {beyond[1]} = {beyond[2]}"


def values_problem(inputs_mm, angles_urad) -> str | None:
    """Why inputs (n, 3) [mm] or angles (n, 3) [urad] about to be written would be refused by
    the reader, or None (the writer's check)."""
    beyond = first_beyond(_columns(inputs_mm, angles_urad))
    return None if beyond is None else f"point {beyond[0] + 1}, {beyond[1]} = {beyond[2]}"


MAX_TIME_S = 1e10  # [s] 317 years: above any measurement's time stamps (Unix seconds included)


def time_problem(time_s) -> str | None:
    """Why time stamps (n,) [s] of a synthetic file are unusable, or None."""
    t = np.asarray(time_s, dtype=float)
    if not np.all(np.isfinite(t)) or np.any(np.abs(t) > MAX_TIME_S):
        return f"the time stamps reach {np.max(np.abs(t)):g} s, beyond {MAX_TIME_S:g} s; give a dwell_s of seconds"
    return None
