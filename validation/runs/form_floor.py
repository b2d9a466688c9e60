"""The model-form floor of a synthetic run: the calibration model at the *true* parameter
values against the truth curve (docs/verification-table1.md, "Model-form floor").

No identification can bring the fit below what the model leaves when every one of its 45
sources is exactly right: that residual is the model's form error on this trajectory, the
floor under every synthetic report's fit RMS. It is reported for the model the run used and
for the paper's model (Eq. 1-8 as written: closed-form chain compliance, no second-order
terms), per angle, overall and by posture group:

- **class** S1 / S2 / S3 (``model.forward.CLASS_NAMES``) of the run's model at the true
  values (one split for both models, so their rows compare);
- **actuators**: "single" where at most one commanded input is non-zero (|x| > ``MOVED``),
  "multi" where two or three are;
- **unloading**: "near" where, for some drive i, within one trajectory step (one stroke
  increment) of the posture the drive unloads or reloads -- the sign of its release
  fx_A,i (Eq. 6: > 0 when the axial load pulls the nut off its loaded flank into the gap)
  differs between this posture and the one before or after it -- or where its actuator's
  travel direction reversed at this posture while the nut is off its flank (fx_A,i > 0:
  the prototype's breakaway band keeps direction memory there, the model's force-only clip
  does not); "far" elsewhere. fx_A and the travel directions are the run's model's at the
  true values.

Every split is a partition of the postures, so n x RMS^2 of a split's groups add up to the
overall one (per angle). The run's fit residual over the same groups stands beside it.

The truth curve (``TruthCurve``) is the prototype's noise-free curve when the run made it
(``truth_from_run``), else the measured curve with the sidecar's sensor offset taken off
(``truth_from_measurement``; its noise stays in, and ``source`` says so). Without preset
values (a real measurement) there is no floor: ``not_available``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from flexcal.calibration.staged_start import is_consistent
from flexcal.model.parameters import ParameterSpace

from ..measurements import Measurement
from ..sidecar import stated_sensor_noise_urad

__all__ = ["TruthCurve", "truth_from_run", "truth_from_measurement", "paper_model_space", "model_name",
           "model_description",
           "posture_groups", "model_form_floor", "not_available", "GROUP_ORDER", "MOVED"]

ANGLES = ("theta_x", "theta_y", "theta_z")
MOVED = 1e-9  # [m] a commanded input above 1 nm counts as moved (commands are written to 1e-9 mm .. 1 nm)
GROUP_ORDER = {"class": ("S1", "S2", "S3"), "actuators": ("single", "multi"), "unloading": ("near", "far")}
NO_TRUE_VALUES = "not available: no true values (the measurement's sidecar holds no preset errors)"


@dataclass(frozen=True, kw_only=True, eq=False)
class TruthCurve:
    """angles (n, 3) [rad] the truth the model is held against; presets (45,) [SI] the true
    source values; source: what the angles are (said in every report)."""

    angles: np.ndarray
    presets: np.ndarray
    source: str

    def __post_init__(self) -> None:
        angles = np.asarray(self.angles, dtype=float)
        if angles.ndim != 2 or angles.shape[1] != 3 or not np.all(np.isfinite(angles)):
            raise ValueError(f"truth angles must be finite with shape (n, 3) [rad], got {angles.shape}")
        object.__setattr__(self, "angles", angles)
        object.__setattr__(self, "presets", np.asarray(self.presets, dtype=float))


def truth_from_run(run, presets: np.ndarray) -> TruthCurve:
    """The prototype's noise-free curve (``PrototypeRun.angles``: what the sensors read
    without noise and offset, sensor effects included) with the scenario's values (45,) [SI]."""
    return TruthCurve(angles=run.angles, presets=presets,
                      source="noise-free prototype curve (made in this run; no sensor noise or offset)")


def truth_from_measurement(measurement: Measurement, space: ParameterSpace) -> TruthCurve | None:
    """The measured curve as truth when its sidecar holds preset errors (None otherwise):
    the sidecar's sensor offset taken off, its noise left in (the source says how much)."""
    presets = measurement.metadata.get("preset_errors")
    if not presets:
        return None
    values = space.build_values({e["name"]: e["value"] for e in presets}, display_units=True)
    sensors = measurement.metadata.get("sensors") or {}
    offset = np.asarray(sensors.get("offset_urad", [0.0] * 3), dtype=float) * 1e-6
    stated = stated_sensor_noise_urad(measurement.metadata)
    noise = np.full(3, np.nan) if stated is None else stated
    if np.all(noise == 0.0):
        what = "noise-free (the sidecar states sensor noise 0)"
    elif np.all(np.isfinite(noise)):
        what = "with the sensor noise the sidecar states (" + ", ".join(f"{v:g}" for v in noise) + " urad) left in"
    else:
        what = "with its sensor noise left in (the sidecar states none)"
    taken = "; the sidecar's sensor offset taken off" if np.any(offset != 0.0) else ""
    return TruthCurve(angles=measurement.angles - offset, presets=values,
                      source=f"measured curve, {what}{taken}")


def paper_model_space(space: ParameterSpace) -> ParameterSpace:
    """The paper's model (Eq. 1-8 as written) on the mount of ``space``: closed-form chain
    compliance (``--model-stiffness closed-form``), no second-order terms (``--no-second-order``)."""
    return dataclasses.replace(space, compliance_factors=(), compliance_slopes=(), compliance_curvatures=(),
                               second_order=False,
                               breakaway_force=None, chain_shortening=(), shortening_slopes=())


def model_name(space: ParameterSpace) -> str:
    """The ``--model`` name of the model a space evaluates: "paper", "consistent" (the chains'
    measured shortening set) or "second-order" (anything else ``--model second-order`` builds,
    its ``--model-stiffness`` and ``--second-order`` variants included)."""
    if (not space.compliance_factors and not space.second_order and space.breakaway_force is None
            and not is_consistent(space)):
        return "paper"
    return "consistent" if is_consistent(space) else "second-order"


def model_description(space: ParameterSpace) -> str:
    """Which model a space evaluates, in the command line's words: what it holds, then its
    ``--model`` name."""
    name = model_name(space)
    if name == "paper":
        return ("the paper's model (Eq. 1-8 as written: closed-form chain stiffness, no second-order terms; "
                "--model paper)")
    stiffness = ("closed-form chain stiffness (Eq. 1)" if not space.compliance_factors else
                 "FEM-informed chain stiffness" + (" following the dimensions" if space.compliance_slopes else "")
                 + (" to second order" if space.compliance_curvatures else ""))
    play = ("" if space.breakaway_force is None
            else f", clearance play state with breakaway force {space.breakaway_force:g} N")
    terms = ("consistent (measured chain shortening, solved with the clearance)" if space.chain_shortening
             else "on" if space.second_order else "off")
    return f"{stiffness}, second-order terms {terms}{play} (--model {name})"


def posture_groups(inputs: np.ndarray, point_class: np.ndarray, release: np.ndarray,
                   directions: np.ndarray) -> dict[str, np.ndarray]:
    """{split: labels (n,)} of the three partitions (module docstring).

    inputs (n, 3) [m] commands; point_class (n,) in {1, 2, 3}; release (n, 3) [m] fx_A of
    D1-D3; directions (n, 3) +-1 travel directions, all in trajectory order."""
    from flexcal.model.forward import CLASS_NAMES

    inputs, release, directions = (np.asarray(a, dtype=float) for a in (inputs, release, directions))
    n = inputs.shape[0]
    moved = np.sum(np.abs(inputs) > MOVED, axis=1)
    off_flank = release > 0.0
    flips = off_flank[1:] != off_flank[:-1]  # (n - 1, 3): the drive unloads or reloads in that step
    crossing = np.zeros((n, 3), dtype=bool)
    crossing[1:] |= flips
    crossing[:-1] |= flips
    reversed_here = np.zeros((n, 3), dtype=bool)
    reversed_here[1:] = directions[1:] != directions[:-1]
    near = np.any(crossing | (reversed_here & off_flank), axis=1)
    return {"class": np.array([CLASS_NAMES[int(c)] for c in point_class]),
            "actuators": np.where(moved <= 1, "single", "multi"),
            "unloading": np.where(near, "near", "far")}


def _stats(error: np.ndarray) -> dict[str, Any]:
    """RMS per angle and max |.| per angle [urad] of an (m, 3) [rad] error; None when m = 0."""
    if error.shape[0] == 0:
        return {"n": 0, "rms_urad": None, "max_abs_urad": None, "max_urad": None}
    rms = np.sqrt(np.mean(error**2, axis=0)) * 1e6
    peak = np.abs(error).max(axis=0) * 1e6
    return {"n": int(error.shape[0]), "rms_urad": dict(zip(ANGLES, rms.tolist())),
            "max_abs_urad": dict(zip(ANGLES, peak.tolist())), "max_urad": float(peak.max())}


def _grouped(error: np.ndarray, groups: dict[str, np.ndarray]) -> dict[str, Any]:
    out = {"all": _stats(error)}
    for split, labels in groups.items():
        out[split] = {label: _stats(error[labels == label]) for label in GROUP_ORDER[split]}
    return out


def model_form_floor(truth: TruthCurve, inputs: np.ndarray, space: ParameterSpace, *,
                     fit_residual: np.ndarray | None = None) -> dict[str, Any]:
    """The ``model_form_floor`` entry of a report.

    truth: the true curve and values; inputs (n, 3) [m] the commands in trajectory order;
    space: the run's model (its mechanism, chain stiffness and second-order switch);
    fit_residual (n, 3) [rad] the run's fitted minus measured angles (None: no fit column).
    Both models run with the default travel directions of ``inputs``, as the calibration
    does. Returns JSON-ready data: the truth's source, the group definitions, and per model
    (the run's first, then the paper's unless they are the same) the RMS and max per angle
    [urad] overall and per group, with the fit's beside them."""
    from flexcal.model.forward import forward

    inputs = np.asarray(inputs, dtype=float)
    if truth.angles.shape != inputs.shape:
        raise ValueError(f"the truth curve has {truth.angles.shape[0]} postures, the inputs {inputs.shape[0]}: "
                         "they must be the same trajectory")
    run = forward(truth.presets, inputs, space=space)
    groups = posture_groups(inputs, run.point_class[0], run.release[0], run.directions)
    paper = paper_model_space(space)
    models = [("run", space, run.angles[0])]
    if ((space.compliance_factors, space.compliance_slopes, space.compliance_curvatures, space.second_order,
         space.breakaway_force, space.chain_shortening)
            != (paper.compliance_factors, paper.compliance_slopes, paper.compliance_curvatures, paper.second_order,
                paper.breakaway_force, paper.chain_shortening)):
        models.append(("paper", paper, forward(truth.presets, inputs, space=paper).angles[0]))
    out: dict[str, Any] = {
        "available": True,
        "truth": truth.source,
        "n_points": int(inputs.shape[0]),
        "units": "urad; error = model at the true values - truth curve",
        "groups": {"class": "S1/S2/S3 of the run's model at the true values (model.forward)",
                   "actuators": f"single: at most one commanded input non-zero (|x| > {MOVED:g} m); "
                                "multi: two or three",
                   "unloading": "near: a drive's release fx_A (run's model at the true values) changes sign within "
                                "one trajectory step before or after the posture, or its actuator reversed here "
                                "while its nut is off its loaded flank (fx_A > 0); far: elsewhere"},
        "models": [{"model": key, "name": model_name(s), "description": model_description(s),
                    "is_paper_model": len(models) == 1 or key == "paper",
                    **_grouped(angles - truth.angles, groups)} for key, s, angles in models],
    }
    if fit_residual is not None:
        out["fit"] = _grouped(np.asarray(fit_residual, dtype=float), groups)
    return out


def not_available(reason: str = NO_TRUE_VALUES) -> dict[str, Any]:
    """The ``model_form_floor`` entry of a run on real data."""
    return {"available": False, "reason": reason}
