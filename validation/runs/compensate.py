"""Closed-loop compensation on the virtual prototype (paper Sec. 4.1, Fig. 9; Sec. 4.3).

Wiring of ``flexcal.calibration.compensation`` (the loop) to the model and the prototype:

1. misalignment curve (a measurement file) -> return offsets of the reciprocal legs
   removed (Sec. 4.2, ``verify.remove_return_offsets``);
2. Sobol screening + improved-PSO identification (``verify.run_verify``);
3. inputs of each target through the calibrated model's inverse (``model.inverse``);
4. drive the prototype rebuilt from the data's sidecar (``bench_from_metadata``), measure;
5. correct with the measured error through the calibrated model's input Jacobian, repeat.

How a target is approached (the paper: "starting from the defined zero posture"): each
target is driven from zero inputs, the sequence of a round being 0, x_1, 0, x_2, ... so
every actuator's travel direction at a target is the sign of its input. A reading is the
posture's angles averaged over ``n_readings`` samples of the stable interval (sensor
noise sigma / sqrt(n_readings)); the measured relative angle of a target is its reading
minus the reading at the zero posture just before it, which also removes the sensor's zero
and whatever slow drift accumulated since the calibration. Targets are relative angles
(``flexcal.validation.runs.targets``). The session clock runs on from the end of the
calibration curve, one ``dwell`` per driven posture.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from flexcal.calibration.compensation import LoopResult, LoopSettings, iterate
from flexcal.calibration.staged_start import is_consistent
from flexcal.model.parameters import ParameterSpace

from ..measurements import Measurement
from ..sidecar import stated_sensor_noise_urad
from .verify import VerifyResult, VerifySettings, run_verify

__all__ = ["Bench", "DriveRecord", "CompensationSettings", "CompensationResult", "approach_sequence",
           "drive_targets", "bench_driver", "bench_effects", "bench_from_metadata", "identified_values",
           "model_zero_angles", "return_offsets", "calibrated_inputs", "small_deflection_inputs",
           "model_input_jacobian", "model_states", "run_compensation", "drives_in_order", "sequence_angles",
           "sequence_jacobian"]

DEFAULT_READINGS = 10  # samples averaged per posture reading (the paper's "stable interval" mean)
DEFAULT_DWELL = 2.0  # [s] per driven posture when the curve has no time step (the scenario default)


@dataclass(frozen=True, kw_only=True, eq=False)
class Bench:
    """The virtual prototype as a test bench. prototype; effects injected into its physics
    (``simulate(effects=...)``); noise (3,) [rad] per-sample sensor noise; offset (3,)
    [rad] sensor zero offset; dwell [s] per posture; n_readings samples per reading;
    seed of the bench's noise stream; start_time [s] of the session clock; description."""

    prototype: Any
    effects: tuple = ()
    noise: np.ndarray = field(default_factory=lambda: np.zeros(3))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    dwell: float = DEFAULT_DWELL
    n_readings: int = DEFAULT_READINGS
    seed: int = 0
    start_time: float = 0.0
    description: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.n_readings < 1 or not self.dwell > 0:
            raise ValueError(f"n_readings={self.n_readings} must be >= 1 and dwell={self.dwell} s > 0")


@dataclass(frozen=True, kw_only=True, eq=False)
class DriveRecord:
    """One round on the bench: inputs (n, 3) [m]; measured (n, 3) [rad] relative angles as
    read; true (n, 3) [rad] the frame's true rotation relative to the zero posture before
    it; point_class (n,) the prototype's class at each target; nut_offsets (n, 3) [m];
    time (2n,) [s] of the driven postures (zero, target, zero, ...)."""

    inputs: np.ndarray
    measured: np.ndarray
    true: np.ndarray
    point_class: np.ndarray
    nut_offsets: np.ndarray
    time: np.ndarray


def approach_sequence(inputs: np.ndarray) -> np.ndarray:
    """(2n, 3) [m]: zero inputs before every target's inputs (n, 3) [m]."""
    inputs = np.asarray(inputs, dtype=float)
    sequence = np.zeros((2 * len(inputs), 3))
    sequence[1::2] = inputs
    return sequence


def drive_targets(bench: Bench, inputs: np.ndarray, *, start_time: float, rng: np.random.Generator) -> DriveRecord:
    """Drive the targets' inputs (n, 3) [m] from the zero posture, read, return a ``DriveRecord``."""
    from ..prototype.mechanism import simulate

    sequence = approach_sequence(inputs)
    time = start_time + bench.dwell * np.arange(len(sequence))
    run = simulate(bench.prototype, sequence, effects=bench.effects, time=time)
    reading_noise = bench.noise / np.sqrt(bench.n_readings)
    readings = run.angles + bench.offset + rng.normal(size=run.angles.shape) * reading_noise
    return DriveRecord(inputs=np.array(inputs, dtype=float), measured=readings[1::2] - readings[0::2],
                       true=run.true_angles[1::2] - run.true_angles[0::2], point_class=run.point_class[1::2],
                       nut_offsets=run.nut_offsets[1::2], time=time)


def bench_driver(bench: Bench, log: list) -> Callable[[np.ndarray], np.ndarray]:
    """``drive_and_measure(inputs) -> measured relative angles`` on ``bench``, keeping the
    session clock and the noise stream (seed stream 4) between calls; appends each
    ``DriveRecord`` to ``log``."""
    rng = np.random.default_rng([bench.seed, 4])  # stream 4: compensation readings (1: errors, 2: curve noise, 3: room)
    clock = [bench.start_time]

    def drive(inputs: np.ndarray) -> np.ndarray:
        record = drive_targets(bench, inputs, start_time=clock[0], rng=rng)
        clock[0] = float(record.time[-1] + bench.dwell)
        log.append(record)
        return record.measured

    return drive


def _provider_from_description(description: str, progress: bool, workers: int | None = 0,
                               scheduler: str | None = None):
    from ..prototype.providers import stiffness_provider

    if description.startswith("FEM"):  # tied cuts say so in their description (tied_fem_provider)
        kind = "fem" if "cuts tied" in description else "fem-rigid"
        return stiffness_provider(kind, progress=progress, workers=workers, scheduler=scheduler)
    if description.startswith("analytic"):
        return stiffness_provider("analytic")
    raise ValueError(f"the sidecar's provider {description!r} is neither FEM nor analytic; cannot rebuild the prototype")


def bench_effects(entries: list) -> tuple:
    """Injector objects for the sidecar's scenario ``effects`` entries (effect library)."""
    if not entries:
        return ()
    from ..effects.library import effects_from_scenario

    return tuple(effects_from_scenario(tuple(dict(e) for e in entries)))


def bench_from_metadata(metadata: dict, space: ParameterSpace, *, n_readings: int = DEFAULT_READINGS,
                        seed: int | None = None, dwell: float = DEFAULT_DWELL, end_time: float = 0.0,
                        progress: bool = False, workers: int | None = 0, scheduler: str | None = None) -> Bench | None:
    """The prototype a virtual-prototype measurement came from, or None for a real one.

    metadata: the measurement's JSON sidecar (``flexcal truth``: preset errors, provider,
    transmission, sensors, effects, seed); dwell [s] per posture (the curve's time step);
    end_time [s]: the curve's last time stamp (the session clock continues one dwell later);
    workers / scheduler: where the FEM segments missing from the cache are built in
    parallel (``fem_provider``; the bench's drives themselves are sequential: each round
    depends on the last, and the prototype's friction and clock carry over)."""
    from ..prototype.mechanism import build_prototype
    from ..prototype.truth import as_built

    presets = metadata.get("preset_errors")
    if not presets or "provider" not in metadata:
        return None
    values = space.build_values({e["name"]: e["value"] for e in presets}, display_units=True)
    mechanism, offsets, drives = as_built(space, values)
    breakaway = float(metadata.get("transmission", {}).get("breakaway_force_n", 2.0))
    prototype = build_prototype(mechanism, [(x0, cl, mu, breakaway) for x0, cl, mu in drives],
                                _provider_from_description(str(metadata["provider"]), progress, workers, scheduler),
                                mount_offsets=offsets)
    sensors = metadata.get("sensors", {})
    stated = stated_sensor_noise_urad(metadata)
    noise_urad = np.zeros(3) if stated is None else stated  # no noise stated: the bench adds none
    entries = list(metadata.get("effects", []))
    return Bench(prototype=prototype, effects=bench_effects(entries),
                 noise=noise_urad * 1e-6,
                 offset=np.asarray(sensors.get("offset_urad", [0.0] * 3), dtype=float) * 1e-6,
                 dwell=dwell, n_readings=n_readings, seed=int(metadata.get("seed", 0) if seed is None else seed),
                 start_time=end_time + dwell,
                 description={"scenario": metadata.get("scenario"), "seed": metadata.get("seed"),
                              "provider": metadata["provider"], "effects": entries,
                              "noise_urad_per_sample": noise_urad.tolist(),
                              "n_readings": n_readings, "dwell_s": dwell})


# --- the calibrated model's side -------------------------------------------------------------

def identified_values(result: VerifyResult, space: ParameterSpace) -> np.ndarray:
    """(45,) [SI] every source at its identified value (nominal if screened out)."""
    return np.asarray(result.values, float).copy()


def unidentified_drive_sources(result: VerifyResult) -> list[str]:
    """The Table 1 drive sources the compensation's inverse relies on (x0, CL, mu) that the
    curve neither identifies nor shows to be irrelevant (a drive that never opens its gap
    does not need its CL or mu): their values are the prior's or the screening's."""
    from flexcal.model.parameters import DRIVE_SOURCE_NAMES

    identifiable = set(result.report.get("identifiable", []))
    hidden = set(result.report.get("not_observable", {}))
    return [n for n in DRIVE_SOURCE_NAMES if n not in identifiable and n not in hidden]


def model_zero_angles(values: np.ndarray, space: ParameterSpace) -> np.ndarray:
    """(3,) [rad] the model's angles at zero inputs (its "defined zero posture")."""
    from flexcal.model.forward import forward

    return forward(values, np.zeros((1, 3)), space=space).angles[0, 0]


def _approach_directions(inputs: np.ndarray) -> np.ndarray:
    """Each input reached straight from zero; any non-zero input counts as a move
    (min_move 0: these inputs are solved, not jittery commands)."""
    from flexcal.model.trajectory import approach_directions

    return approach_directions(inputs, min_move=0.0)


def drives_in_order(space: ParameterSpace) -> bool:
    """Whether the model is evaluated along the bench's ordered sequence (0, x_1, 0, x_2, ...,
    ``approach_sequence``) instead of target by target: with the clearance's play state
    (``breakaway_force``: each nut's offset is carried from posture to posture, so a target's
    angles depend on the postures driven before it) or the consistent model (its compiled solve
    has no closed-form input Jacobian, ``model.inverse.forward_jacobian``)."""
    return space.breakaway_force is not None or is_consistent(space)


# The input step of the ordered model's Jacobian by central differences [m]: ~1e-4 of the
# workspace's inputs (mm), so the difference keeps ~8 digits of the angles (the fixed point's
# tolerance 1e-13 m against 1e-7 m of travel) and its truncation (curvature x step) is far below
# the micro-radian errors the loop corrects.
SEQUENCE_STEP = 1e-7
# Newton on the ordered model (``calibrated_inputs``): stop at this angle error [rad] (1e-5 urad,
# far below the bench's noise and the loop's tolerance) or after this many steps.
SEQUENCE_TOL, SEQUENCE_MAX_ITER = 1e-11, 30


def sequence_angles(values: np.ndarray, inputs: np.ndarray, space: ParameterSpace) -> np.ndarray:
    """(n, 3) [rad]: the model with ``values`` driven as the bench drives the targets' inputs
    (n, 3) [m] (0, x_1, 0, x_2, ..., in order, compiled engine): each target's angles minus
    those at the zero posture just before it (what the bench measures, ``drive_targets``)."""
    from flexcal.model.forward import forward

    angles = forward(values, approach_sequence(inputs), space=space).angles[0]
    return angles[1::2] - angles[0::2]


def sequence_jacobian(values: np.ndarray, inputs: np.ndarray, space: ParameterSpace) -> np.ndarray:
    """d theta_k / d x_k (n, 3, 3) [rad/m] of ``sequence_angles`` by central differences of
    ``SEQUENCE_STEP``, every target's input i moved at once (6 ordered runs; a target's
    dependence on the inputs before it, through the nuts' offsets, is not in its block)."""
    x = np.asarray(inputs, dtype=float)
    out = np.zeros(x.shape + (3,))
    for i in range(3):
        step = np.zeros(3)
        step[i] = SEQUENCE_STEP
        out[:, :, i] = (sequence_angles(values, x + step, space) - sequence_angles(values, x - step, space)) / (
            2.0 * SEQUENCE_STEP)
    return out


def _ordered_inverse(values: np.ndarray, targets: np.ndarray, space: ParameterSpace, start: np.ndarray) -> np.ndarray:
    """Inputs (n, 3) [m] with ``sequence_angles`` = ``targets`` (n, 3) [rad]: Newton from ``start``
    with ``sequence_jacobian``, halving a step that does not reduce the largest error."""
    from flexcal.calibration.compensation import correction_step

    x = np.array(start, dtype=float)
    error = sequence_angles(values, x, space) - targets
    for _ in range(SEQUENCE_MAX_ITER):
        if np.max(np.abs(error)) <= SEQUENCE_TOL:
            return x
        step = correction_step(sequence_jacobian(values, x, space), error)
        for _half in range(20):
            trial = x + step
            trial_error = sequence_angles(values, trial, space) - targets
            if np.max(np.abs(trial_error)) < np.max(np.abs(error)):
                break
            step = 0.5 * step
        else:
            break
        x, error = trial, trial_error
    if np.max(np.abs(error)) > 1e3 * SEQUENCE_TOL:
        point = int(np.argmax(np.max(np.abs(error), axis=1)))
        raise ValueError(f"the calibrated model's ordered inverse did not converge for target {point} (error "
                         f"{np.max(np.abs(error[point])) * 1e6:.3g} urad); drop or move that target")
    return x


def calibrated_inputs(values: np.ndarray, targets: np.ndarray, space: ParameterSpace) -> np.ndarray:
    """Inputs (n, 3) [m] that bring the model with ``values`` (45,) [SI] to each relative
    target (n, 3) [rad] from its zero posture (step 3). ``ValueError`` if not invertible.
    A model that ``drives_in_order``: along the bench's sequence (``sequence_angles``)."""
    from flexcal.model.forward import ConvergenceError
    from flexcal.model.inverse import inverse

    if drives_in_order(space):
        return _ordered_inverse(values, np.asarray(targets, dtype=float), space,
                                small_deflection_inputs(targets, space))
    absolute = model_zero_angles(values, space) + np.asarray(targets, dtype=float)
    guess = small_deflection_inputs(targets, space)
    try:
        return inverse(absolute, _approach_directions(guess), space_values=values, space=space).inputs
    except ConvergenceError as error:
        raise ValueError(f"the calibrated model's inverse failed for target {error.point}: {error}; "
                         "drop or move that target") from None


def small_deflection_inputs(targets: np.ndarray, space: ParameterSpace) -> np.ndarray:
    """Inputs (n, 3) [m] of the uncalibrated small-deflection model (nominal, linear:
    relative angles = G x with G its (3, 3) [rad/m] input gain) for relative targets (n, 3)."""
    from flexcal.model.assembly import mechanism_matrices

    gain = mechanism_matrices(space.nominal_full, space).input_gain[0, 3:, 3:]
    return np.linalg.solve(gain, np.asarray(targets, dtype=float).T).T


def model_input_jacobian(values: np.ndarray, inputs: np.ndarray, space: ParameterSpace) -> np.ndarray:
    """d theta / d x (n, 3, 3) [rad/m] of the model with ``values`` at inputs (n, 3) [m]; a
    model that ``drives_in_order``: of its ordered run (``sequence_jacobian``)."""
    from flexcal.model.assembly import mechanism_matrices
    from flexcal.model.forward import solve_matrices
    from flexcal.model.inverse import forward_jacobian

    if drives_in_order(space):
        return sequence_jacobian(values, inputs, space)
    matrices = mechanism_matrices(values, space)
    directions = _approach_directions(inputs)
    solution = solve_matrices(matrices, np.asarray(inputs, dtype=float), directions, engine="numpy")
    return forward_jacobian(matrices, solution, directions)


def model_states(values: np.ndarray, inputs: np.ndarray, space: ParameterSpace) -> tuple[np.ndarray, np.ndarray]:
    """(class (n,) "S1"/"S2"/"S3", release fx_A (n, 3) [m]) of the model at inputs (n, 3)
    [m]: each driving chain's distance from its clearance zero (paper Fig. 12 d, h, l)."""
    from flexcal.model.forward import CLASS_NAMES, forward

    if drives_in_order(space):  # at each target as the bench reaches it
        result = forward(values, approach_sequence(inputs), space=space)
        return (np.array([CLASS_NAMES[int(c)] for c in result.point_class[0, 1::2]]), result.release[0, 1::2])
    result = forward(values, inputs, _approach_directions(inputs), space=space)
    return np.array([CLASS_NAMES[int(c)] for c in result.point_class[0]]), result.release[0]


def return_offsets(measurement: Measurement) -> dict[int, np.ndarray]:
    """{leg: offset (3,) [rad]} that ``verify.remove_return_offsets`` takes off each
    reciprocal leg (reading at the leg's end minus the reading before it, after the
    earlier legs' removal); legs that do not return are absent."""
    from .verify import remove_return_offsets

    removed = measurement.angles - remove_return_offsets(measurement)
    out = {}
    for leg in dict.fromkeys(measurement.leg.tolist()):
        index = np.flatnonzero(measurement.leg == leg)
        before, last = index[0] - 1, index[-1]
        if before >= 0 and np.any(removed[last] != removed[before]):
            out[int(leg)] = removed[last] - removed[before]
    return out


# --- the whole run ---------------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class CompensationSettings:
    """verify: identification settings (the return offsets are always removed first);
    loop: tolerance, rounds, gain."""

    verify: VerifySettings = field(default_factory=VerifySettings)
    loop: LoopSettings = field(default_factory=LoopSettings)


@dataclass(frozen=True, kw_only=True, eq=False)
class CompensationResult:
    """targets (n, 3) [rad] relative; values (45,) [SI] identified; verify: the
    identification; first_inputs (n, 3) [m] from the inverse; model_class (n,) and
    release (n, 3) [m] of the calibrated model at the final inputs; curve_release (m, 3)
    [m] of the calibrated model along the calibration curve (Fig. 12 d, h, l);
    return_offsets: {leg: (3,) [rad]} removed from the curve before identification (Sec. 4.2);
    uncalibrated: the
    small-deflection model's inputs driven (None without a bench); loop (None without a
    bench); records: the loop's drives in order; bench: its description (None: real data)."""

    targets: np.ndarray
    values: np.ndarray
    verify: VerifyResult
    first_inputs: np.ndarray
    model_class: np.ndarray
    release: np.ndarray
    curve_release: np.ndarray
    return_offsets: dict
    uncalibrated: DriveRecord | None = None
    loop: LoopResult | None = None
    records: tuple[DriveRecord, ...] = ()
    bench: dict | None = None


def run_compensation(measurement: Measurement, targets: np.ndarray, space: ParameterSpace,
                     settings: CompensationSettings = CompensationSettings(), *, bench: Bench | None = None,
                     truth=None, progress: bool = True, budget=None) -> CompensationResult:
    """Fig. 9 on ``measurement`` for relative ``targets`` (n, 3) [rad]; without a bench it
    stops after step 3 (the inputs to send). truth: the model-form floor's truth
    (``runs.form_floor.TruthCurve``; None: "not available" in the report); budget: the
    identification's model-error budget (``run_verify``'s; --method map/free only)."""
    from flexcal.model.forward import forward

    log = print if progress else (lambda *a, **k: None)
    verify_settings = dataclasses.replace(settings.verify, remove_offset=True)
    result = run_verify(measurement, space, verify_settings, truth=truth, progress=progress, budget=budget)
    values = identified_values(result, space)
    weak = unidentified_drive_sources(result)
    if weak:
        import sys

        print(f"compensate: warning: the curve does not identify {', '.join(weak)}, which the inverse relies on; "
              f"their values are the prior's (--method map) or the screening's: measure a designed trajectory "
              f"(flexcal design) to identify them", file=sys.stderr)
    curve_release = forward(values, measurement.inputs, space=space).release[0]
    offsets = return_offsets(measurement)
    first = calibrated_inputs(values, targets, space)
    if bench is None:
        model_class, release = model_states(values, first, space)
        return CompensationResult(targets=targets, values=values, verify=result, first_inputs=first,
                                  model_class=model_class, release=release, curve_release=curve_release,
                                  return_offsets=offsets)
    records: list[DriveRecord] = []
    drive = bench_driver(bench, records)
    log(f"compensate: driving {len(targets)} targets with the small-deflection model's inputs (baseline)")
    drive(small_deflection_inputs(targets, space))
    uncalibrated = records.pop()
    log("compensate: calibrated inputs, then the closed loop")
    loop = iterate(targets, first, drive, lambda x: model_input_jacobian(values, x, space), settings.loop)
    log(f"compensate: {loop.n_corrections} corrective round(s), converged: {loop.converged}")
    model_class, release = model_states(values, loop.final.inputs, space)
    return CompensationResult(targets=targets, values=values, verify=result, first_inputs=first,
                              model_class=model_class, release=release, curve_release=curve_release,
                              return_offsets=offsets,
                              uncalibrated=uncalibrated, loop=loop,
                              records=tuple(records), bench=bench.description)
