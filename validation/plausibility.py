"""Plausibility of a measurement against its mount: do the columns hold the units they name?

A file with its angles in rad under ``theta_*_urad`` columns, or its inputs in m under
``xa*_mm``, reads without an error (every value is a finite number within the reader's
limits) and is then fitted to nonsense: a fit RMS of ~900 urad, no base parameter, or a
diagnosis that names ``sensor_scale``. Such a file betrays itself by its **gain**: the angle
change per input change. The mount's nominal gain ``J`` (3 angles x 3 drives) [rad/m] is
the small-deflection model's ``d theta / d x`` at zero input (``flexcal.model``), ~1-3
rad/m for the reference mount. Per drive i the measured gain ratio ``k_i`` is the least
squares fit of

    angles - mean  ~  sum_i k_i (x_i - mean) J[:, i]

and per angle a the ratio ``r_a`` fits ``angle_a - mean ~ r_a (J (x - mean))_a``. A unit
mistake multiplies a ratio by a power of ten (rad for urad: 1e-6; mrad: 1e-3; m for mm:
1e3; um for mm: 1e-3); the data of a genuine mount with its error sources (+-10 %
dimensions, clearance, hysteresis, a different payload) differ from the nominal gain by a
factor of ~2-5 at most. The ratios of the prototype's own table1 data are 0.94-1.0, and
``tests/test_plausibility.py`` holds table1, paper and a full-range draw to 0.8-1.2. A ratio is refused beyond ``GAIN_RATIO_LIMIT`` = 20 (or
below 1/20), and only when it is off by more than ``CONFIDENCE_Z`` standard errors, so a
drive that barely moves under noise is never judged on its noise: 20 leaves a factor 4
above the largest legitimate difference and a factor 50 below the smallest unit mistake
(1e3), and it still catches inches for mm (25.4). A factor-10 mistake (cm for mm) lies in
the band of honest differences and is not caught.

The **spans** name the cause: a file whose angles span 1e-6 of the workspace (+-1, +-5, +-3
mrad) and whose inputs span the stroke has angles in rad; one whose inputs span 1e-3 of the
stroke has inputs in m. The stroke of drive i is the input that alone reaches the edge of
the workspace on the nominal model (the standard trajectory's amplitude,
``flexcal.model.trajectory``). A span beyond ``SPAN_LIMIT`` times the workspace or stroke is
refused on its own: no measurement of this mount moves that far (the model diverges at a
few times the stroke). Small spans alone are never refused: a genuine trajectory may use a
tenth of the workspace.

Pure functions over arrays; ``flexcal.validation.cli.options.read_data`` calls
``unit_problem`` once for every command that reads a measurement, and
``--skip-unit-check`` reads the file as it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["MountScale", "UnitEvidence", "mount_scale", "unit_evidence", "unit_problem", "GAIN_RATIO_LIMIT",
           "SPAN_LIMIT", "CONFIDENCE_Z"]

GAIN_RATIO_LIMIT = 20.0  # [-] measured/nominal gain beyond this (or below its inverse) is a unit mistake (module doc)
SPAN_LIMIT = 20.0  # [-] a span beyond this many workspaces / strokes is no measurement of the mount
CONFIDENCE_Z = 3.0  # [-] a ratio is judged off only when off by more than this many standard errors
JUDGED_SHARE = 0.1  # [-] an angle is judged when its predicted span is >= this share of the largest one
MIN_MOVE = 1e-9  # [m] a drive whose input moves less does not move (model.trajectory.MIN_MOVE)
# fewer points leave the ratios' standard errors meaningless (a 3-point file can be exactly
# linear); every identification needs more (45 sources / 3 angles = 15, the diagnosis 20)
MIN_POINTS = 10

_ANGLE_UNITS = (("rad", 1e-6), ("mrad", 1e-3), ("deg", 1e-6 / (math.pi / 180.0)), ("nrad", 1e3))
_INPUT_UNITS = (("m", 1e3), ("inch", 25.4), ("um", 1e-3), ("nm", 1e-6))
_ANGLE_COLUMNS = ("theta_x_urad", "theta_y_urad", "theta_z_urad")
_INPUT_COLUMNS = ("xa1_mm", "xa2_mm", "xa3_mm")


@dataclass(frozen=True, kw_only=True)
class MountScale:
    """gain (3 angles, 3 drives) [rad/m]: d theta / d x of the nominal small-deflection model
    at zero input; stroke (3,) [m]: the input of each drive that alone reaches the edge of
    the workspace; workspace (3,) [rad]: half-ranges of theta_x, theta_y, theta_z."""

    gain: np.ndarray
    stroke: np.ndarray
    workspace: np.ndarray


@dataclass(frozen=True, kw_only=True)
class UnitEvidence:
    """What a measurement says about its units (module doc). drive_ratio, drive_std (3,):
    k_i and its standard error (nan: drive i does not move); angle_ratio, angle_std (3,):
    r_a and its standard error (nan: angle a is not judged; all nan below MIN_POINTS points); angle_span (3,): span of each
    angle / (2 workspace); input_span (3,): span of each input / (2 stroke)."""

    drive_ratio: np.ndarray
    drive_std: np.ndarray
    angle_ratio: np.ndarray
    angle_std: np.ndarray
    angle_span: np.ndarray
    input_span: np.ndarray


def mount_scale(mechanism=None) -> MountScale:
    """The ``MountScale`` of ``mechanism`` (``MechanismParams``; the reference mount by default)."""
    from flexcal.model.assembly import mechanism_matrices
    from flexcal.model.parameters import parameter_space

    space = parameter_space(mechanism)
    workspace = np.asarray(space.mechanism.workspace, dtype=float)  # the mount's own (MechanismParams.workspace)
    gain = mechanism_matrices(space.nominal_full, space).input_gain[0, 3:, 3:]
    with np.errstate(divide="ignore"):
        stroke = np.min(workspace[:, None] / np.abs(gain), axis=0)  # as model.trajectory.standard_trajectory
    return MountScale(gain=gain, stroke=stroke, workspace=workspace)


def _ratio_fit(design: np.ndarray, target: np.ndarray, dof: int) -> tuple[np.ndarray, np.ndarray]:
    """Least squares ``target ~ design @ k`` (design (m, p)): k (p,) and standard errors (p,)
    (inf where the design cannot tell the ratios apart or no degree of freedom is left)."""
    k, _, rank, _ = np.linalg.lstsq(design, target, rcond=None)
    if rank < design.shape[1] or dof <= 0:
        return k, np.full(k.shape, np.inf)
    residual = target - design @ k
    variance = float(residual @ residual) / dof
    with np.errstate(divide="ignore", invalid="ignore"):
        covariance = variance * np.linalg.inv(design.T @ design)
    return k, np.sqrt(np.abs(np.diag(covariance)))


def unit_evidence(inputs: np.ndarray, angles: np.ndarray, scale: MountScale) -> UnitEvidence:
    """``UnitEvidence`` of inputs (n, 3) [m] and angles (n, 3) [rad] as read (SI)."""
    x = np.asarray(inputs, dtype=float)
    a = np.asarray(angles, dtype=float)
    n = x.shape[0]
    xc, ac = x - x.mean(axis=0), a - a.mean(axis=0)
    input_range = np.ptp(x, axis=0)
    angle_span = np.ptp(a, axis=0) / (2.0 * scale.workspace)
    input_span = input_range / (2.0 * scale.stroke)
    drive_ratio, drive_std = np.full(3, np.nan), np.full(3, np.nan)
    angle_ratio, angle_std = np.full(3, np.nan), np.full(3, np.nan)
    moving = np.flatnonzero(input_range > MIN_MOVE)
    if moving.size and n >= MIN_POINTS:
        # per drive: sum_i k_i (x_i - mean) J[:, i], stacked over the three angles
        design = np.stack([(xc[:, i, None] * scale.gain[None, :, i]).ravel() for i in moving], axis=1)
        k, std = _ratio_fit(design, ac.ravel(), dof=3 * (n - 1) - moving.size)
        drive_ratio[moving], drive_std[moving] = k, std
        predicted = xc[:, moving] @ scale.gain[:, moving].T  # (n, 3) [rad]
        relative = np.ptp(predicted, axis=0) / scale.workspace
        for j in np.flatnonzero(relative >= JUDGED_SHARE * relative.max()) if relative.max() > 0 else ():
            r, s = _ratio_fit(predicted[:, j, None], ac[:, j], dof=n - 2)
            angle_ratio[j], angle_std[j] = r[0], s[0]
    return UnitEvidence(drive_ratio=drive_ratio, drive_std=drive_std, angle_ratio=angle_ratio, angle_std=angle_std,
                        angle_span=angle_span, input_span=input_span)


def _off(ratio: np.ndarray, std: np.ndarray) -> np.ndarray:
    """(3,) bool: the ratio is beyond the limit by more than CONFIDENCE_Z standard errors."""
    size, margin = np.abs(ratio), CONFIDENCE_Z * std
    with np.errstate(invalid="ignore"):
        return np.isfinite(ratio) & np.isfinite(std) & ((size + margin < 1.0 / GAIN_RATIO_LIMIT)
                                                        | (size - margin > GAIN_RATIO_LIMIT))


def _likely_unit(factor: float, units) -> str | None:
    """The unit whose factor is within 2x of ``factor`` (log-nearest), or None."""
    name, value = min(units, key=lambda u: abs(math.log10(u[1]) - math.log10(factor)))
    return name if abs(math.log10(value) - math.log10(factor)) < math.log10(2.0) else None


def _geometric_mean(values: np.ndarray) -> float:
    """Geometric mean of |values|; 0 if any is 0."""
    size = np.abs(values)
    if np.any(size == 0):
        return 0.0
    return float(np.exp(np.mean(np.log(size))))


def unit_problem(evidence: UnitEvidence) -> str | None:
    """One line naming the likely unit mistake, or None when the file fits the mount."""
    drives, angles = _off(evidence.drive_ratio, evidence.drive_std), _off(evidence.angle_ratio, evidence.angle_std)
    if drives.any() or angles.any():
        ratios = np.concatenate([evidence.drive_ratio[drives], evidence.angle_ratio[angles]])
        factor = _geometric_mean(ratios)
        if angles.any() and not drives.any():
            side, columns = "angles", [_ANGLE_COLUMNS[j] for j in np.flatnonzero(angles)]
        elif drives.any() and not angles.any():
            side, columns = "inputs", [_INPUT_COLUMNS[i] for i in np.flatnonzero(drives)]
        else:  # every ratio is off: the spans tell angles from inputs
            with np.errstate(divide="ignore"):
                angle_off = abs(math.log10(max(float(np.max(evidence.angle_span)), 1e-300)))
                input_off = abs(math.log10(max(float(np.max(evidence.input_span)), 1e-300)))
            side = "angles" if angle_off >= input_off else "inputs"
            columns = list(_ANGLE_COLUMNS if side == "angles" else _INPUT_COLUMNS)
        if not (np.isfinite(factor) and factor > 0):
            return (f"the {side} do not follow the mount ({', '.join(columns)}): gain 0 x the mount's; check the "
                    f"file, or pass --skip-unit-check to read it as it is")
        units = _ANGLE_UNITS if side == "angles" else _INPUT_UNITS
        unit = _likely_unit(factor, units)
        if side == "angles":
            said, span = "urad", f"angle span {float(np.max(evidence.angle_span)):.2g} x the workspace"
        else:
            said, span = "mm", f"input span {float(np.max(evidence.input_span)):.2g} x the stroke"
        if unit is None:
            return (f"the {side}' unit looks wrong: the file says {said} ({', '.join(columns)}); gain {factor:.2g} x "
                    f"the mount's, {span}; check the unit or pass --skip-unit-check to read the file as it is")
        exact = dict(units)[unit]
        scaled = 1.0 / exact if side == "angles" else exact
        return (f"{side} look like {unit}: the file says {said} ({', '.join(columns)}); gain {factor:.2g} x the "
                f"mount's, {span}; multiply the column(s) by {scaled:.6g} or pass --skip-unit-check to read the file "
                f"as it is")
    far = [(span, _ANGLE_COLUMNS[j], "the workspace") for j, span in enumerate(evidence.angle_span)] + \
          [(span, _INPUT_COLUMNS[i], "the stroke") for i, span in enumerate(evidence.input_span)]
    span, column, what = max(far)
    if span > SPAN_LIMIT:
        return (f"column {column} spans {span:.3g} x {what} of the mount: no measurement of this mount moves that "
                f"far; check the unit, or the mount in the sidecar, or pass --skip-unit-check to read the file as it is")
    return None
