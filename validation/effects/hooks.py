"""Hook for effects injected into the virtual prototype's physics.

An effect is any object with a ``name`` (str) and ``parameters`` (mapping of JSON-able
values, recorded in the run's provenance) and any subset of these methods, called by
``flexcal.validation.prototype.mechanism.simulate`` at each trajectory point, in this order and in
the order the effects are given:

``modify_screw_position(actuator, command, position, context) -> position``
    actuator 0..2 (D1..D3), command x_cmd [m], position: the screw position so far
    ``x_cmd + x0`` [m] (after earlier effects); returns the screw position [m] the
    transmission then works from (lead error, periodic screw error, drift...).
``modify_stiffness(stiffness, context) -> stiffness``
    stiffness (6, 5, 6, 6): K_jj [SI] of the five segments of chains L1..L3, D1..D3;
    return the modified array (a weaker hinge, a cracked strut, temperature). With tied cuts
    (the provider fem) the frame takes the change to each chain's K_chain by the segments'
    congruences (``mechanism.tied_chain_stiffness``; docs/effects.md, "Effects on tied cuts"),
    as for the K_jj that ``modify_mechanism`` and ``modify_loaded_mechanism`` change.
``modify_mechanism(conditions, context) -> conditions``
    ``PointConditions`` of the point (stiffness of every segment, dead forces on the
    payload frame, actuator contact stiffness); return a modified copy
    (``dataclasses.replace``) -- thermal softening, an extra cable force, a weaker hinge.
``modify_loaded_mechanism(conditions, axial_loads, context) -> conditions``
    the same, for conditions that depend on the point's own loads: axial_loads (6,) [N]
    (tension positive, L1..L3, D1..D3) of the current iterate; the prototype solves them
    together with the equilibrium and the nut offsets (fixed point to
    ``SolverSettings.load_tolerance``), so the result is consistent with this point's
    loads, not the previous point's (load-dependent stiffness, gravity sag).
``measure(angles, context) -> angles``
    sensor side only: the frame's true rotation vector (3,) [rad] -> what the sensor
    reports (offsets, scale errors, cross-talk). Noise belongs to the scenario, not here.

``context`` is an ``EffectContext``: point index, command (3,) [m], travel direction of
each actuator (+1/-1, docs/conventions.md), the previous point's result (or None), the
time [s] and dwell since the previous point [s], the room temperature [degC], and the
history (commands and times up to this point, results of the earlier points) from which
path-dependent effects (friction memory, creep, lost steps) compute their state.
Effects must be deterministic functions of their parameters and the context (seeded
randomness is drawn at construction), so equal inputs give equal runs.

``room_temperature(time, seed)`` is the slowly varying room temperature of a run: the
same function feeds the context and the ``temperature_c`` column of ``flexcal truth``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping, Protocol, runtime_checkable

import numpy as np

__all__ = ["Effect", "EffectContext", "PointConditions", "PointResult", "effect_record", "room_temperature",
           "REFERENCE_TEMPERATURE_C"]

REFERENCE_TEMPERATURE_C = 20.0  # [degC] temperature at which the mechanism has its nominal dimensions


@runtime_checkable
class Effect(Protocol):
    """Minimal protocol: a name and parameters; the hook methods are optional (module docstring)."""

    name: str
    parameters: Mapping[str, Any]


@dataclass(frozen=True, kw_only=True, eq=False)
class PointResult:
    """The physics' answer at one point, as effects see it for the next point.

    angles (3,) [rad] (true rotation vector of the frame), pose (6,) [m, rad], axial_loads
    (6,) [N] (tension positive, chains L1..L3, D1..D3), nut_offsets (3,) [m].
    """

    angles: np.ndarray
    pose: np.ndarray
    axial_loads: np.ndarray
    nut_offsets: np.ndarray


@dataclass(frozen=True, kw_only=True, eq=False)
class EffectContext:
    """What an effect sees at one point.

    point_index; command (3,) [m]; direction (3,) of +1/-1; previous: ``PointResult`` or
    None; time [s] of the point; dwell [s] since the previous point (0 at the first);
    temperature [degC] of the room; past_commands (k + 1, 3) [m], past_times (k + 1,) [s]
    and past_temperatures (k + 1,) [degC] of points 0..k (this one last); history:
    ``PointResult`` of points 0..k-1.
    """

    point_index: int
    command: np.ndarray
    direction: np.ndarray
    previous: PointResult | None
    time: float = 0.0
    dwell: float = 0.0
    temperature: float = REFERENCE_TEMPERATURE_C
    past_commands: np.ndarray | None = None
    past_times: np.ndarray | None = None
    past_temperatures: np.ndarray | None = None
    history: tuple = ()


@dataclass(frozen=True, kw_only=True, eq=False)
class PointConditions:
    """What the physics uses at one point, open to ``modify_mechanism``.

    segment_stiffness (6, 5, 6, 6): K_jj of every segment [SI]; frame_forces: tuple of
    (force (3,) [N] world, point (3,) [m] in the frame body, i.e. design coordinates) --
    the payload weight first; actuator_stiffness (3,) [N/m].
    """

    segment_stiffness: np.ndarray
    frame_forces: tuple
    actuator_stiffness: np.ndarray

    def __post_init__(self) -> None:
        if np.shape(self.segment_stiffness) != (6, 5, 6, 6):
            raise ValueError(f"segment_stiffness must have shape (6, 5, 6, 6), got {np.shape(self.segment_stiffness)}")
        if np.shape(self.actuator_stiffness) != (3,) or not np.all(np.asarray(self.actuator_stiffness) > 0):
            raise ValueError("actuator_stiffness must be three values > 0 N/m")


def effect_record(effect: Any) -> dict[str, Any]:
    """Provenance entry ``{"name": ..., "parameters": {...}}`` of an effect.

    Raises ``ValueError`` if the effect has no name or none of the hook methods.
    """
    name = getattr(effect, "name", None)
    if not isinstance(name, str) or not name:
        raise ValueError(f"effect {effect!r} needs a non-empty string attribute 'name'")
    hooks = ("modify_screw_position", "modify_stiffness", "modify_mechanism", "modify_loaded_mechanism", "measure")
    if not any(callable(getattr(effect, h, None)) for h in hooks):
        raise ValueError(f"effect {name!r} has none of the hook methods {', '.join(hooks)}")
    parameters = getattr(effect, "parameters", None)
    if parameters is None and dataclasses.is_dataclass(effect):
        parameters = {f.name: getattr(effect, f.name) for f in dataclasses.fields(effect) if f.name != "name"}
    return {"name": name, "parameters": dict(parameters or {})}


def room_temperature(time: np.ndarray, seed: int = 0) -> np.ndarray:
    """Room temperature (n,) [degC] at the times (n,) [s] of a run with ``seed``.

    A lab's slow thermal weather: a linear trend (|rate| <= 1 K/h), an air-conditioning
    cycle (period 150..400 s, amplitude 0.1..0.3 K) and a slower swing (period 0.5..2 h,
    amplitude <= 0.3 K) around ``REFERENCE_TEMPERATURE_C`` + an offset within +-0.5 K.
    Deterministic in (seed, time), drawn from its own stream of the seed (stream 3;
    streams 1 and 2 are the scenario's error draws and sensor noise), so the same seed
    gives the same column whatever effects are injected.
    """
    t = np.asarray(time, dtype=float)
    rng = np.random.default_rng([int(seed), 3])
    offset, rate = rng.uniform(-0.5, 0.5), rng.uniform(-1.0, 1.0) / 3600.0
    cycle_period, cycle_amplitude = rng.uniform(150.0, 400.0), rng.uniform(0.1, 0.3)
    slow_period, slow_amplitude = rng.uniform(1800.0, 7200.0), rng.uniform(0.0, 0.3)
    cycle_phase, slow_phase = rng.uniform(0.0, 2 * np.pi, size=2)
    return (REFERENCE_TEMPERATURE_C + offset + rate * t
            + cycle_amplitude * np.sin(2 * np.pi * t / cycle_period + cycle_phase)
            + slow_amplitude * np.sin(2 * np.pi * t / slow_period + slow_phase))
