"""Prototype-side physics of the effect library (issue #7): injectors for
``flexcal.validation.prototype.mechanism.simulate`` (hooks in ``effects.hooks``).

Each injector is a frozen dataclass with its physical parameters in SI (per-actuator or
per-channel values as 3-tuples, per-chain as 6-tuples L1..L3, D1..D3), a ``name`` (the
effect id) and ``parameters`` (JSON-able). They are deliberately richer than the model
terms of ``effects.terms`` (docs/effects.md): extra harmonics, load-dependent friction,
a thermal lag, two creep time constants... Path-dependent state (friction memory, creep,
lost steps) is recomputed from the context's history, so an injector holds no state and
equal runs give equal results.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from .terms import SCREW_LEAD, relaxed
from .hooks import REFERENCE_TEMPERATURE_C

__all__ = ["Drift", "SensorCrosstalk", "SensorScale", "LeadError", "FrictionHysteresis", "CouplingWindup",
           "LargeDeflection", "GravitySag", "Thermal", "Creep", "StepLoss", "SensorInterpolation",
           "STEPS_PER_REVOLUTION", "LOAD_REFERENCE", "ANGLE_REFERENCE"]

STEPS_PER_REVOLUTION = 200  # full steps of a 1.8 deg stepper motor: one step = SCREW_LEAD / 200 = 5 um
LOAD_REFERENCE = 1e3  # [N] chain loads are ~1 kN (docs/prototype.md)
ANGLE_REFERENCE = 1e-3  # [rad] hinge rotations are a few mrad on the standard trajectory


def _vector(value, n: int, what: str) -> tuple[float, ...]:
    array = np.asarray(value, dtype=float)
    if array.ndim == 0:
        array = np.full(n, float(array))
    if array.shape != (n,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{what} must be one number or {n} finite numbers, got {value!r}")
    return tuple(float(v) for v in array)


class _Injector:
    """Shared parts: vector fields normalized to tuples of floats, ``parameters`` from the fields."""

    _vectors: dict[str, int] = {}

    def __post_init__(self) -> None:
        for name, n in self._vectors.items():
            object.__setattr__(self, name, _vector(getattr(self, name), n, f"{self.name}.{name}"))

    @property
    def parameters(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "name"}


def _reversals(context) -> np.ndarray:
    """(3,) travel-direction reversals of each actuator up to this point."""
    from flexcal.model.trajectory import travel_directions

    d = travel_directions(context.past_commands)
    return np.sum(np.diff(d, axis=0) != 0, axis=0)


# ---------------------------------------------------------------- sensor side

@dataclass(frozen=True, kw_only=True)
class Drift(_Injector):
    """Sensor drift: rate (3,) [rad/s] per channel, curvature (3,) [rad/s^2] (a drift that
    speeds up or settles), reversal_step (3,) [rad] added at every travel-direction reversal
    of any actuator (per-stroke return offsets). measured = true + rate t + curvature t^2
    + reversal_step * (number of reversals so far)."""

    rate: tuple = (0.0, 0.0, 0.0)
    curvature: tuple = (0.0, 0.0, 0.0)
    reversal_step: tuple = (0.0, 0.0, 0.0)
    name: str = "drift"
    _vectors = {"rate": 3, "curvature": 3, "reversal_step": 3}

    def measure(self, angles, context):
        t = context.time - context.past_times[0]
        steps = float(np.sum(_reversals(context))) if any(self.reversal_step) else 0.0
        return (angles + np.asarray(self.rate) * t + np.asarray(self.curvature) * t**2
                + np.asarray(self.reversal_step) * steps)


def _rotation(vector) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.asarray(vector, dtype=float)).as_matrix()


@dataclass(frozen=True, kw_only=True)
class SensorCrosstalk(_Injector):
    """Sensor axes misaligned: the sensor frame is rotated by ``rotation`` (3,) [rad]
    (rotation vector) against the mechanism frame, and its axes are not orthogonal: each
    channel's axis leans towards the next by ``shear`` (3,) [rad] (x towards y, y towards z,
    z towards x). measured = S R^T theta with R the exact rotation, S = I + shear terms."""

    rotation: tuple = (0.0, 0.0, 0.0)
    shear: tuple = (0.0, 0.0, 0.0)
    name: str = "sensor_crosstalk"
    _vectors = {"rotation": 3, "shear": 3}

    def measure(self, angles, context):
        shear = np.eye(3)
        shear[0, 1], shear[1, 2], shear[2, 0] = self.shear
        return shear @ (_rotation(self.rotation).T @ angles)


@dataclass(frozen=True, kw_only=True)
class SensorScale(_Injector):
    """Per-channel scale error: measured = (1 + scale) * theta, scale (3,) [-]."""

    scale: tuple = (0.0, 0.0, 0.0)
    name: str = "sensor_scale"
    _vectors = {"scale": 3}

    def measure(self, angles, context):
        return angles * (1.0 + np.asarray(self.scale))


@dataclass(frozen=True, kw_only=True)
class SensorInterpolation(_Injector):
    """OUT OF THE LIBRARY (no model term): the sensor's sub-division (interpolation) error,
    periodic in the measured angle itself: measured_a = theta_a + amplitude_a sin(2 pi
    theta_a / period + phase_a); amplitude (3,) [rad], period [rad], phase (3,) [rad]."""

    amplitude: tuple = (0.0, 0.0, 0.0)
    period: float = 0.4e-3
    phase: tuple = (0.0, 0.0, 0.0)
    name: str = "sensor_interpolation"
    _vectors = {"amplitude": 3, "phase": 3}

    def measure(self, angles, context):
        return angles + np.asarray(self.amplitude) * np.sin(2 * np.pi * angles / self.period + np.asarray(self.phase))


# ---------------------------------------------------------------- screw side

@dataclass(frozen=True, kw_only=True)
class LeadError(_Injector):
    """Ball-screw lead error at the nut's place s on the screw [m] (the screw position the
    hook receives), zero at the home position s = 0 where the drive was zeroed:
    Δs = slope s + amplitude [sin(2 pi s / lead + phase) - sin(phase)]
    + second [sin(4 pi s / lead + phase_2) - sin(phase_2)]; slope (3,) [-], amplitude,
    second (3,) [m], phase, phase_2 (3,) [rad], lead [m/rev]."""

    slope: tuple = (0.0, 0.0, 0.0)
    amplitude: tuple = (0.0, 0.0, 0.0)
    phase: tuple = (0.0, 0.0, 0.0)
    second: tuple = (0.0, 0.0, 0.0)
    phase_2: tuple = (0.0, 0.0, 0.0)
    lead: float = SCREW_LEAD
    name: str = "lead_error"
    _vectors = {"slope": 3, "amplitude": 3, "phase": 3, "second": 3, "phase_2": 3}

    def modify_screw_position(self, actuator, command, position, context):
        turn, i = 2 * np.pi * position / self.lead, actuator
        return (position + self.slope[i] * position
                + self.amplitude[i] * (np.sin(turn + self.phase[i]) - np.sin(self.phase[i]))
                + self.second[i] * (np.sin(2 * turn + self.phase_2[i]) - np.sin(self.phase_2[i])))


@dataclass(frozen=True, kw_only=True)
class FrictionHysteresis(_Injector):
    """Dahl friction of each nut/guide with load-dependent Coulomb level, acting through the
    drive's compliance: the friction force F = F_c z with F_c = force + load_coefficient |N|
    (N: the chain's load at the previous point [N]) and the generalized Dahl state
    dz/dx = |1 - z sgn(dx)|^exponent / length (rate-independent, z in [-1, 1]);
    the nut lags by F / stiffness: Δs = -F / stiffness. force (3,) [N]; load_coefficient [-];
    length [m]; exponent [-] (1 = classical Dahl); stiffness [N/m] of screw + coupling."""

    force: tuple = (0.0, 0.0, 0.0)
    load_coefficient: float = 0.0
    length: float = 40e-6
    exponent: float = 1.5
    stiffness: float = 2.0e8
    name: str = "friction_hysteresis"
    _vectors = {"force": 3}

    def __post_init__(self) -> None:
        super().__post_init__()
        if not (self.length > 0 and self.stiffness > 0 and self.exponent > 0):
            raise ValueError("friction_hysteresis length, exponent and stiffness must be > 0")

    def _state(self, context, actuator: int) -> float:
        """Dahl state after the command history, exact per step: with w = 1 - z sgn(dx),
        dw/d|x| = -w^e / length, so w = w0 exp(-|dx|/length) (e = 1) or
        w = (w0^(1-e) + (e-1) |dx| / length)^(1/(1-e))."""
        z, e = 0.0, self.exponent
        for dx in np.diff(context.past_commands[:, actuator]):
            if dx == 0.0:
                continue
            s, w0, travel = np.sign(dx), 1.0 - z * np.sign(dx), abs(dx) / self.length
            if e == 1.0:
                w = w0 * np.exp(-travel)
            elif w0 <= 0.0:
                w = 0.0
            else:
                w = (w0 ** (1.0 - e) + (e - 1.0) * travel) ** (1.0 / (1.0 - e))
            z = s * (1.0 - w)
        return z

    def modify_screw_position(self, actuator, command, position, context):
        load = 0.0 if context.previous is None else abs(float(context.previous.axial_loads[3 + actuator]))
        coulomb = self.force[actuator] + self.load_coefficient * load
        return position - coulomb * self._state(context, actuator) / self.stiffness


@dataclass(frozen=True, kw_only=True)
class CouplingWindup(_Injector):
    """Torsional wind-up of the flexible motor coupling. The screw torque to hold the axial
    load N [N] (previous point, tension +) and overcome the nut friction is
    T = -(lead / 2 pi) N + d (preload_torque + friction_radius |N|) (d: travel direction);
    the coupling twists by T / torsional_stiffness and the screw lags the motor by
    Δs = -(lead / 2 pi) T / torsional_stiffness. torsional_stiffness (3,) [N m/rad];
    friction_radius (3,) [m] (friction coefficient x mean screw radius); preload_torque
    (3,) [N m]; lead [m/rev]."""

    torsional_stiffness: tuple = (1e3, 1e3, 1e3)
    friction_radius: tuple = (0.0, 0.0, 0.0)
    preload_torque: tuple = (0.0, 0.0, 0.0)
    lead: float = SCREW_LEAD
    name: str = "coupling_windup"
    _vectors = {"torsional_stiffness": 3, "friction_radius": 3, "preload_torque": 3}

    def modify_screw_position(self, actuator, command, position, context):
        if context.previous is None:
            return position  # nothing has moved yet: the coupling is relaxed
        load = float(context.previous.axial_loads[3 + actuator])
        radius = self.lead / (2 * np.pi)
        torque = -radius * load + context.direction[actuator] * (self.preload_torque[actuator]
                                                                 + self.friction_radius[actuator] * abs(load))
        return position - radius * torque / self.torsional_stiffness[actuator]


@dataclass(frozen=True, kw_only=True)
class Thermal(_Injector):
    """Thermal expansion of the drive: each screw/strut lengthens by expansion (3,) [m/K]
    times its temperature minus ``REFERENCE_TEMPERATURE_C``; the parts follow the room
    temperature (context) with the first-order lag time_constant [s] (0: no lag)."""

    expansion: tuple = (0.0, 0.0, 0.0)
    time_constant: float = 0.0
    name: str = "thermal"
    _vectors = {"expansion": 3}

    def _part_temperature(self, context) -> float:
        history = context.past_temperatures
        if self.time_constant <= 0 or history is None:
            return context.temperature
        return float(relaxed(np.asarray(history)[:, None], context.past_times, self.time_constant)[-1, 0])

    def modify_screw_position(self, actuator, command, position, context):
        return position + self.expansion[actuator] * (self._part_temperature(context) - REFERENCE_TEMPERATURE_C)


@dataclass(frozen=True, kw_only=True)
class Creep(_Injector):
    """Creep of each drive's contact (nut, bearings) under its axial load: two Kelvin-Voigt
    elements, Δs = sum_j compliance_j * y_j with y_j the load N [N] (tension +) relaxed
    with time_constant_j [s] over the dwell at each point (the load of point k-1 held
    until point k). compliance (3,) [m/N] per actuator, fraction [-] of it in the slow
    element, time_constants (2,) [s]."""

    compliance: tuple = (0.0, 0.0, 0.0)
    fraction: float = 0.3
    time_constants: tuple = (10.0, 100.0)
    name: str = "creep"
    _vectors = {"compliance": 3, "time_constants": 2}

    def modify_screw_position(self, actuator, command, position, context):
        if not context.history:
            return position  # the load is applied at the first point: no creep yet
        loads = np.array([r.axial_loads[3 + actuator] for r in context.history] + [0.0])
        loads[-1] = loads[-2]  # the current point's load is not known before it is solved
        times = context.past_times
        fast, slow = (relaxed(loads[:, None], times, tau)[-1, 0] for tau in self.time_constants)
        # creep is the relaxed minus the initial elastic part (the elastic one is the mechanism's own)
        creep = (1 - self.fraction) * (fast - loads[0]) + self.fraction * (slow - loads[0])
        return position + self.compliance[actuator] * creep


@dataclass(frozen=True, kw_only=True)
class StepLoss(_Injector):
    """Lost motor steps: events ((actuator, travel [m], n_steps), ...): when the actuator's
    travelled path first exceeds ``travel`` it loses n_steps full steps of step_size [m]
    against its travel direction at that moment, for the rest of the run (persistent)."""

    events: tuple = ()
    step_size: float = SCREW_LEAD / STEPS_PER_REVOLUTION
    name: str = "step_loss"

    def __post_init__(self) -> None:
        events = tuple((int(a), float(s), int(n)) for a, s, n in self.events)
        for actuator, travel, _ in events:
            if actuator not in (0, 1, 2) or not travel >= 0:
                raise ValueError(f"step_loss event actuator={actuator}, travel={travel} needs actuator 0..2, travel >= 0 m")
        object.__setattr__(self, "events", events)

    def modify_screw_position(self, actuator, command, position, context):
        x = context.past_commands[:, actuator]
        steps = np.diff(x)
        path = np.concatenate([[0.0], np.cumsum(np.abs(steps))])
        lost = 0.0
        for event_actuator, travel, n_steps in self.events:
            if event_actuator != actuator or path[-1] <= travel:
                continue
            k = int(np.argmax(path > travel))  # first point past the travel; the move k-1 -> k lost the steps
            lost -= np.sign(steps[k - 1]) * n_steps * self.step_size
        return position + lost


# ---------------------------------------------------------------- stiffness side

@functools.lru_cache(maxsize=4)
def reference_angle_gain(mechanism=None) -> tuple:
    """d theta / d x (3 angles x 3 actuators) [rad/m] of the linear model of ``mechanism``
    (``MechanismParams``; None: the reference mechanism), row-major (9,)."""
    from flexcal.model.assembly import mechanism_matrices
    from flexcal.model.parameters import parameter_space

    space = parameter_space(mechanism)
    gain = mechanism_matrices(space.nominal_full, space).input_gain[0, 3:, 3:]
    return tuple(float(v) for v in gain.ravel())


@dataclass(frozen=True, kw_only=True)
class LargeDeflection(_Injector):
    """Geometric stiffening of the hinges at large rotation: chain c's segment stiffness is
    scaled by 1 + coefficient_c (|phi| / ANGLE_REFERENCE)^2, phi = G x the frame rotation
    the commands x (3,) [m] ask for (each hinge bends by about the frame's rotation; the
    stiffness must be set before the point is solved, so it comes from the command through
    the mechanism's linear gain G (3, 3) [rad/m], ``angle_gain`` row-major, default the
    reference mechanism's). coefficient (6,) [-] L1..L3, D1..D3."""

    coefficient: tuple = (0.0,) * 6
    angle_gain: tuple | None = None
    name: str = "large_deflection"
    _vectors = {"coefficient": 6}

    def modify_stiffness(self, stiffness, context):
        gain = np.asarray(self.angle_gain if self.angle_gain is not None else reference_angle_gain()).reshape(3, 3)
        bend = float(np.sum((gain @ context.command) ** 2)) / ANGLE_REFERENCE**2
        return stiffness * (1.0 + np.asarray(self.coefficient) * bend)[:, None, None, None]


@dataclass(frozen=True, kw_only=True)
class GravitySag(_Injector):
    """Load-dependent stiffness of the load path that carries the payload's weight:
    (a) the ball contacts of each drive (Hertz-like): the actuator stiffness k_a becomes
    k_a ((|N_i| + preload) / (load_reference + preload))^exponent_i, N_i the drive's load
    at this point [N] (solved with the equilibrium: ``modify_loaded_mechanism``); (b) the
    hinges: chain c's segment stiffness is scaled by 1 + coefficient_c N_c / LOAD_REFERENCE
    (compressed hinges soften, stretched ones stiffen). exponent (3,) [-] (1/3 for a Hertz contact, 0 = linear); preload [N];
    load_reference [N]; coefficient (6,) [-] L1..L3, D1..D3."""

    exponent: tuple = (0.0, 0.0, 0.0)
    preload: float = 500.0
    load_reference: float = 1500.0
    coefficient: tuple = (0.0,) * 6
    name: str = "gravity_sag"
    _vectors = {"exponent": 3, "coefficient": 6}

    def modify_loaded_mechanism(self, conditions, axial_loads, context):
        loads = np.asarray(axial_loads, dtype=float)
        factor = 1.0 + np.asarray(self.coefficient) * loads / LOAD_REFERENCE
        if np.any(factor <= 0.1):
            raise ValueError(f"gravity_sag coefficients {self.coefficient} make a chain stiffness vanish at loads "
                             f"{loads} N; use smaller coefficients")
        contact = ((np.abs(loads[3:]) + self.preload) / (self.load_reference + self.preload)) ** np.asarray(self.exponent)
        return dataclasses.replace(conditions, segment_stiffness=conditions.segment_stiffness * factor[:, None, None, None],
                                   actuator_stiffness=conditions.actuator_stiffness * contact)
