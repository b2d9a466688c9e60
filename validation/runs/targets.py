"""Target postures of the compensation run (paper Sec. 4.3, Fig. 13 validation points).

Targets are **relative** angles: the rotation from the posture at zero inputs (the
paper's "defined zero posture") to the wanted posture, (theta_x, theta_y, theta_z)
[rad] in the mechanism frame. The paper computes "the required relative actuation
inputs ... starting from the defined zero posture"; a relative target is what a user
asks of the mount ("tip by 2 mrad"), and reading it relative to the zero posture takes
the sensor's zero and its slow drift out of every reading (docs/compensation.md).

Targets file (CSV, one row per target, header required)::

    theta_x_urad,theta_y_urad,theta_z_urad
    500,-2000,1000
    -250,3500,0

Values in microradians relative to the zero posture; other columns are ignored; rows are
driven in file order. Each target must lie inside the mount's workspace (``workspace``:
``MechanismParams.workspace``, a mount file's ``[workspace] half_range_mrad``; by default
the reference mount's, |theta_x| <= 1 mrad, |theta_y| <= 5 mrad, |theta_z| <= 3 mrad);
larger ones are refused.

The default set (``default_targets``) spreads ``n`` points over 80 % of the workspace box
with the (unscrambled) Halton sequence, so it never coincides with the calibration
trajectory's single-actuator sweeps (the Fig. 13 split between sampling and validation
points) and is the same on every run.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from flexcal.model.trajectory import WORKSPACE

from ..output import write_text

__all__ = ["TARGET_COLUMNS", "DEFAULT_N_TARGETS", "DEFAULT_FILL", "default_targets", "read_targets",
           "write_targets", "check_targets"]

TARGET_COLUMNS = ("theta_x_urad", "theta_y_urad", "theta_z_urad")
DEFAULT_N_TARGETS = 30
DEFAULT_FILL = 0.8  # fraction of each workspace half-range the default targets span


def _workspace(workspace) -> np.ndarray:
    return WORKSPACE if workspace is None else np.asarray(workspace, dtype=float)


def check_targets(targets: np.ndarray, *, where: str = "targets", workspace=None) -> np.ndarray:
    """(n, 3) [rad] finite and inside ``workspace`` (3,) [rad] half-ranges (default the
    reference mount's), else ``ValueError`` naming the row (1-based)."""
    workspace = _workspace(workspace)
    targets = np.asarray(targets, dtype=float)
    if targets.ndim != 2 or targets.shape[1] != 3 or targets.shape[0] == 0:
        raise ValueError(f"{where}: need an (n, 3) array of relative angles with n >= 1, got shape {targets.shape}")
    bad = ~np.all(np.isfinite(targets), axis=1) | np.any(np.abs(targets) > workspace * (1 + 1e-9), axis=1)
    if np.any(bad):
        row = int(np.argmax(bad))
        raise ValueError(f"{where}: target {row + 1} = {np.round(targets[row] * 1e6, 3).tolist()} urad is not finite "
                         f"or outside the workspace +-{np.round(workspace * 1e6).astype(int).tolist()} urad")
    return targets


def default_targets(n: int = DEFAULT_N_TARGETS, fill: float = DEFAULT_FILL, *, workspace=None) -> np.ndarray:
    """(n, 3) [rad] relative targets from the unscrambled Halton sequence (bases 2, 3, 5),
    first point (the origin) skipped, mapped onto +-fill x the ``workspace`` (3,) [rad]
    half-ranges (default the reference mount's)."""
    from scipy.stats import qmc

    if n < 1 or not 0.0 < fill <= 1.0:
        raise ValueError(f"need n >= 1 (got {n}) and 0 < fill <= 1 (got {fill})")
    unit = qmc.Halton(d=3, scramble=False).random(n + 1)[1:]
    return (2.0 * unit - 1.0) * fill * _workspace(workspace)


def read_targets(path: str | os.PathLike, *, workspace=None) -> np.ndarray:
    """Relative targets (n, 3) [rad] from a CSV with columns theta_x_urad, theta_y_urad,
    theta_z_urad (module docstring), inside ``workspace`` (3,) [rad] half-ranges (default
    the reference mount's). ``FileNotFoundError`` / ``ValueError`` naming the row."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"targets file {path} does not exist")
    with path.open(newline="") as handle:
        reader = csv.DictReader(handle)
        header = [h.strip() for h in (reader.fieldnames or [])]
        missing = [c for c in TARGET_COLUMNS if c not in header]
        if missing:
            raise ValueError(f"{path}: row 1 (header) lacks column(s) {', '.join(missing)} "
                             f"(expected {','.join(TARGET_COLUMNS)}, in urad relative to the zero posture)")
        rows = []
        for number, raw in enumerate(reader, start=2):
            row = {(k or "").strip(): (v or "").strip() for k, v in raw.items()}
            if not any(row.values()):
                continue
            values = []
            for column in TARGET_COLUMNS:
                try:
                    values.append(float(row[column]))
                except ValueError:
                    raise ValueError(f"{path}: row {number}, column {column!r}: {row[column]!r} is not a number") \
                        from None
            rows.append(values)
    if not rows:
        raise ValueError(f"{path}: no target rows")
    return check_targets(np.array(rows) * 1e-6, where=str(path), workspace=workspace)


def write_targets(path: str | os.PathLike, targets: np.ndarray) -> None:
    """Write relative targets (n, 3) [rad] in the targets-file format (urad, 6 decimals)."""
    path = Path(path)
    lines = [",".join(TARGET_COLUMNS)] + [",".join(f"{v * 1e6:.6f}" for v in row) for row in np.asarray(targets)]
    write_text(path, "\n".join(lines) + "\n")
