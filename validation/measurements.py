"""Measurement files: misalignment curves as CSV plus a JSON sidecar (DESIGN.md "Data formats").

One row per sampled posture. Required columns, in the field's units:

``point, time_s, leg, xa1_mm, xa2_mm, xa3_mm, theta_x_urad, theta_y_urad, theta_z_urad``

Optional columns are numeric and carry their unit in the name (``temperature_c``, …).
The sidecar ``<name>.json`` holds provenance (generator, seed, preset errors, injected
effects), checked against ``validation/sidecar.py``'s schema; its ``n_points`` must equal
the CSV's data rows. Files are bounded before reading (``MAX_TABLE_BYTES``, ``MAX_POINTS``). The same reader loads synthetic and real measurements; it rejects a bad file
with a ``ValueError`` naming the row (1-based, header = row 1) and the column.

Inside, everything is SI: inputs [m], angles [rad], time [s].
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Measurement", "REQUIRED_COLUMNS", "read_measurement", "write_measurement",
           "sidecar_path", "read_trajectory", "MAX_POINTS", "MAX_TABLE_BYTES"]

REQUIRED_COLUMNS = ("point", "time_s", "leg", "xa1_mm", "xa2_mm", "xa3_mm",
                    "theta_x_urad", "theta_y_urad", "theta_z_urad")
INPUT_COLUMNS = REQUIRED_COLUMNS[3:6]
ANGLE_COLUMNS = REQUIRED_COLUMNS[6:9]
_UNIT_SUFFIXES = ("_mm", "_urad", "_s", "_c", "_k", "_n", "_um", "_deg", "_pct", "_count")
# the file's limits, shared with every writer (flexcal truth refuses up front what they refuse)
from .measurement_limits import (MAX_INDEX, MAX_POINTS, MAX_TABLE_BYTES, first_beyond,  # noqa: E402
                                 values_problem)


@dataclass(frozen=True, kw_only=True)
class Measurement:
    """A misalignment curve. Shapes: n = number of points.

    point (n,) int; time (n,) [s]; leg (n,) int; inputs (n, 3) [m] commanded actuator
    positions; angles (n, 3) [rad] measured θx, θy, θz; extras: optional columns by
    name (file units, as named); metadata: the JSON sidecar (empty if none).
    """

    point: np.ndarray
    time: np.ndarray
    leg: np.ndarray
    inputs: np.ndarray
    angles: np.ndarray
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.point)
        for name, value, shape in (("time", self.time, (n,)), ("leg", self.leg, (n,)),
                                   ("inputs", self.inputs, (n, 3)), ("angles", self.angles, (n, 3))):
            if np.shape(value) != shape:
                raise ValueError(f"Measurement.{name} has shape {np.shape(value)}, expected {shape}")
        for name, value in self.extras.items():
            if np.shape(value) != (n,):
                raise ValueError(f"extra column {name!r} has shape {np.shape(value)}, expected ({n},)")

    @property
    def n_points(self) -> int:
        return len(self.point)


def sidecar_path(csv_path: str | os.PathLike) -> Path:
    return Path(csv_path).with_suffix(".json")


def _parse_number(text: str, row: int, column: str, integer: bool = False) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"row {row}, column {column!r}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"row {row}, column {column!r}: {text!r} is not finite")
    if integer and value != int(value):
        raise ValueError(f"row {row}, column {column!r}: {text!r} must be an integer")
    if integer and abs(value) > MAX_INDEX:
        raise ValueError(f"row {row}, column {column!r}: {text!r} is too large for an index (at most {MAX_INDEX:g})")
    return value


def _csv_text(path: Path, what: str) -> str:
    """The text of a CSV file, its size bounded before reading (MAX_TABLE_BYTES), UTF-8
    (a byte-order mark, spreadsheet programs' "CSV UTF-8", is dropped), without NUL."""
    from flexcal.geometry.schema import read_text

    text = read_text(path, max_bytes=MAX_TABLE_BYTES, what=what)
    if "\0" in text:
        raise ValueError(f"{path}: holds NUL bytes, so it is not a CSV text file; export it as CSV")
    return text


def _csv_rows(reader, path: Path):
    """(row number, cells) from row 2 on; a CSV syntax error is a ValueError naming the row."""
    row_number = 1
    while True:
        row_number += 1
        try:
            raw = next(reader)
        except StopIteration:
            return
        except csv.Error as error:
            raise ValueError(f"{path}: row {row_number} is not valid CSV ({error})") from None
        yield row_number, raw


def read_measurement(path: str | os.PathLike) -> Measurement:
    """Load and check a measurement CSV (and its JSON sidecar if present).

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` naming the row and
    column of the first bad value.
    """
    path = Path(path)
    reader = csv.reader(io.StringIO(_csv_text(path, "measurement file")))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise ValueError(f"{path}: empty file (expected a header row {','.join(REQUIRED_COLUMNS)})") from None
    except csv.Error as error:
        raise ValueError(f"{path}: row 1 (header) is not valid CSV ({error})") from None
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise ValueError(f"{path}: row 1 (header) lacks required column(s) {', '.join(missing)}")
    duplicates = sorted({h for h in header if header.count(h) > 1})
    if duplicates:
        raise ValueError(f"{path}: row 1 (header) repeats column(s) {', '.join(duplicates)}")
    extras_names = [h for h in header if h not in REQUIRED_COLUMNS]
    for name in extras_names:
        if not name.lower().endswith(_UNIT_SUFFIXES):
            raise ValueError(f"{path}: row 1 (header), column {name!r}: optional columns must name their "
                             f"unit with a suffix such as {', '.join(_UNIT_SUFFIXES)}")
    rows = []
    for row_number, raw in _csv_rows(reader, path):
        if not raw or all(not cell.strip() for cell in raw):
            continue
        if len(raw) != len(header):
            raise ValueError(f"{path}: row {row_number} has {len(raw)} values, the header has {len(header)}")
        if len(rows) == MAX_POINTS:
            raise ValueError(f"{path}: more than {MAX_POINTS} data rows (points); split the measurement")
        values = {}
        try:
            for column, cell in zip(header, raw):
                values[column] = _parse_number(cell.strip(), row_number, column,
                                               integer=column in ("point", "leg"))
        except ValueError as error:  # name the file: diagnose and compensate show it as is
            raise ValueError(f"{path}: {error}") from None
        if values["leg"] < 0:
            raise ValueError(f"{path}: row {row_number}, column 'leg': must be >= 0")
        if rows:
            if values["point"] <= rows[-1][1]["point"]:
                raise ValueError(f"{path}: row {row_number}, column 'point': points must increase")
            if values["time_s"] < rows[-1][1]["time_s"]:
                raise ValueError(f"{path}: row {row_number}, column 'time_s': time must not decrease")
        rows.append((row_number, values))
    if not rows:
        raise ValueError(f"{path}: no data rows")

    def column(name: str) -> np.ndarray:
        return np.array([values[name] for _, values in rows])

    beyond = first_beyond({name: column(name) for name in (*INPUT_COLUMNS, *ANGLE_COLUMNS, "time_s")})
    if beyond is not None:
        index, name, message = beyond
        raise ValueError(f"{path}: row {rows[index][0]}, column {name!r}: {message}")

    from .sidecar import read_sidecar

    side = sidecar_path(path)
    metadata: dict[str, Any] = read_sidecar(side, n_rows=len(rows)) if side.is_file() else {}
    return Measurement(
        point=column("point").astype(int),
        time=column("time_s"),
        leg=column("leg").astype(int),
        inputs=np.column_stack([column(c) for c in INPUT_COLUMNS]) * 1e-3,
        angles=np.column_stack([column(c) for c in ANGLE_COLUMNS]) * 1e-6,
        extras={name: column(name) for name in extras_names},
        metadata=metadata,
    )


TRAJECTORY_COLUMNS = INPUT_COLUMNS


def read_trajectory(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(inputs (n, 3) [m], leg (n,) int) of a trajectory CSV: columns xa1_mm, xa2_mm, xa3_mm
    [mm] and optionally leg (an integer >= 0; a blank cell or no column: 1), e.g. ``flexcal
    design``'s trajectory.csv; other columns are ignored. ``ValueError`` naming the file
    and the row (header = row 1) for a short row, a cell that is not a number, a leg that
    is not an integer, an input beyond the file limit (``measurement_limits``), more than
    MAX_POINTS rows or more than MAX_TABLE_BYTES bytes."""
    path = Path(path)
    reader = csv.reader(io.StringIO(_csv_text(path, "trajectory file")))
    try:
        header = [h.strip() for h in next(reader)]
    except (StopIteration, csv.Error):
        raise ValueError(f"{path}: no header row (expected {','.join(TRAJECTORY_COLUMNS)}[,leg])") from None
    for column in TRAJECTORY_COLUMNS:
        if column not in header:
            raise ValueError(f"{path}: row 1 (header) lacks column {column!r}")
    at = {name: header.index(name) for name in (*TRAJECTORY_COLUMNS, "leg") if name in header}
    inputs, legs, row_numbers = [], [], []
    for row_number, raw in _csv_rows(reader, path):
        if not raw or all(not cell.strip() for cell in raw):
            continue
        if len(raw) != len(header):
            raise ValueError(f"{path}: row {row_number} has {len(raw)} values, the header has {len(header)}")
        if len(inputs) == MAX_POINTS:
            raise ValueError(f"{path}: more than {MAX_POINTS} rows (points); split the trajectory")
        try:
            inputs.append([_parse_number(raw[at[c]].strip(), row_number, c) for c in TRAJECTORY_COLUMNS])
            cell = raw[at["leg"]].strip() if "leg" in at else ""
            leg = _parse_number(cell, row_number, "leg", integer=True) if cell else 1
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None
        if leg < 0:
            raise ValueError(f"{path}: row {row_number}, column 'leg': {cell} must be >= 0")
        legs.append(int(leg))
        row_numbers.append(row_number)
    if not inputs:
        raise ValueError(f"{path}: no rows")
    inputs_mm = np.array(inputs)
    beyond = first_beyond(dict(zip(TRAJECTORY_COLUMNS, inputs_mm.T)))
    if beyond is not None:
        index, name, message = beyond
        raise ValueError(f"{path}: row {row_numbers[index]}, column {name!r}: {message}")
    return inputs_mm * 1e-3, np.array(legs)


def write_measurement(path: str | os.PathLike, measurement: Measurement) -> None:
    """Write the CSV (and the sidecar JSON if ``metadata`` is not empty), atomically.

    Inputs are written in mm with 9 decimals (1 pm), angles in µrad with 6 decimals
    (1 prad): far below any sensor's resolution, so a round trip is lossless for use.
    """
    from .output import write_json, write_text

    path = Path(path)
    # rounded as written, so the check sees what the reader will
    problem = values_problem(np.round(measurement.inputs * 1e3, 9), np.round(measurement.angles * 1e6, 6))
    if problem:
        raise ValueError(f"{path}: not written: {problem} (the reader would refuse it)")
    header = list(REQUIRED_COLUMNS) + list(measurement.extras)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for k in range(measurement.n_points):
        row = [str(int(measurement.point[k])), f"{measurement.time[k]:.6f}", str(int(measurement.leg[k]))]
        row += [f"{v * 1e3:.9f}" for v in measurement.inputs[k]]
        row += [f"{v * 1e6:.6f}" for v in measurement.angles[k]]
        row += [f"{measurement.extras[name][k]:.9g}" for name in measurement.extras]
        writer.writerow(row)
    write_text(path, buffer.getvalue())
    if measurement.metadata:
        write_json(sidecar_path(path), measurement.metadata)
