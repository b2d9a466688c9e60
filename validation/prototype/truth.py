"""Synthetic truth: a scenario's preset errors built into the virtual prototype, driven
along its trajectory, read by noisy sensors, written as a measurement (paper Sec. 3.3).

The physics is the prototype's (``flexcal.validation.prototype.mechanism``): FEM segment stiffness
of the as-built chains, exact kinematics, play-with-friction transmission, gravity. The
analytic model is never used to make the data; it only defines the parameter meanings
(``ParameterSpace``) the scenario is written in.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from flexcal.geometry.params import MechanismParams
from flexcal.model.parameters import DIMENSION_FIELDS, ParameterSpace

from ..measurements import Measurement
from .equilibrium import NonConvergenceError
from .mechanism import PrototypeRun, build_prototype, prepare_prototype, simulate
from ..effects.hooks import room_temperature
from .scenario import Scenario

__all__ = ["as_built", "check_scenario", "make_truth", "prepare_truth", "TruthResult", "why_no_equilibrium", "heaviest_payload"]


def as_built(space: ParameterSpace, values: np.ndarray) -> tuple[MechanismParams, dict[str, tuple[float, float]],
                                                                  list[tuple[float, float, float]]]:
    """The as-built mechanism of an error vector (45,) [SI].

    Returns (mechanism with each chain's w, a, l, t1, t2 replaced; mount offsets
    {chain: (d [m], Phi [rad])} of L1-L3; [(x0 [m], CL [m], mu [-])] of D1-D3).
    """
    values = np.asarray(values, dtype=float)
    if values.shape != (len(space.parameters),):
        raise ValueError(f"error vector must have {len(space.parameters)} entries, got {values.shape}")
    by_name = dict(zip(space.all_names, values))
    chains = []
    for placement in space.mechanism.chains:
        changes = {field: by_name[f"{placement.name}.{symbol}"] for symbol, field in DIMENSION_FIELDS.items()}
        chains.append(dataclasses.replace(placement, chain=dataclasses.replace(placement.chain, **changes)))
    mechanism = dataclasses.replace(space.mechanism, chains=tuple(chains))
    offsets = {name: (by_name[f"{name}.d"], by_name[f"{name}.phi"]) for name in ("L1", "L2", "L3")}
    drives = [(by_name[f"{name}.x0"], by_name[f"{name}.CL"], by_name[f"{name}.mu"]) for name in ("D1", "D2", "D3")]
    return mechanism, offsets, drives


@dataclass(frozen=True, kw_only=True, eq=False)
class TruthResult:
    """measurement: what the sensors read (the file); run: the prototype's full state."""

    measurement: Measurement
    run: PrototypeRun


def check_scenario(scenario: Scenario) -> np.ndarray:
    """The times [s] of ``scenario``'s points; ValueError, before any physics, for what the
    measurement file's reader would refuse (one set of limits: sensor figures, inputs, times)."""
    from ..measurement_limits import inputs_problem, sensor_problem, time_problem

    with np.errstate(over="ignore", invalid="ignore"):  # an overflowing dwell is refused just below
        time = np.arange(scenario.inputs.shape[0]) * scenario.dwell
    problem = (sensor_problem(scenario.noise * 1e6, scenario.offset * 1e6) or inputs_problem(scenario.inputs * 1e3)
               or time_problem(time))
    if problem:
        raise ValueError(f"scenario {scenario.name}: {problem}")
    return time


def prepare_truth(scenario: Scenario, provider: Callable) -> None:
    """Build now what ``make_truth`` of ``scenario`` will ask ``provider`` for (its as-built
    prototype's FEM, ``mechanism.prepare_prototype``), e.g. on a thread beside other work; the
    FEM cache then holds it."""
    mechanism, offsets, _ = as_built(scenario.space, scenario.values)
    prepare_prototype(mechanism, provider, mount_offsets=offsets)


def make_truth(scenario: Scenario, provider: Callable, *, effects: tuple = (), progress: bool = False,
               generator: str = "flexcal truth") -> TruthResult:
    """Drive the as-built prototype of ``scenario`` along its trajectory and measure.

    provider: segment stiffness provider (FEM or analytic, ``flexcal.validation.prototype.segments``);
    effects: effect objects injected into the physics (gap diagnosis), after the ones the
    scenario's ``[[effects]]`` tables name (``effects.library.effects_from_scenario``). The
    points are ``scenario.dwell`` apart in time; the room temperature
    (``effects.hooks.room_temperature`` of the scenario seed) reaches the effects and is
    written as column ``temperature_c`` whatever effects are injected. Sensor noise is
    Gaussian per channel from its own stream of the scenario seed, so the same seed
    gives the same file; offsets are added as given.
    """
    from ..effects.library import effects_from_scenario

    time = check_scenario(scenario)
    mechanism, offsets, drives = as_built(scenario.space, scenario.values)
    transmissions = [(x0, cl, mu, scenario.breakaway_force) for x0, cl, mu in drives]
    prototype = build_prototype(mechanism, transmissions, provider, mount_offsets=offsets)
    temperature = room_temperature(time, scenario.seed)
    effects = effects_from_scenario(scenario.effects, scenario.space.mechanism) + tuple(effects)
    try:
        run = simulate(prototype, scenario.inputs, effects=effects, progress=progress, time=time,
                       temperature=temperature)
    except NonConvergenceError as error:
        reason = why_no_equilibrium(prototype, scenario.inputs, str(error), scenario.space.mechanism)
        if reason is None:
            raise
        raise ValueError(f"scenario {scenario.name}: {reason}") from error
    noise_rng = np.random.default_rng([scenario.seed, 2])  # stream 2: sensors (stream 1 drew the errors)
    angles = run.angles + scenario.offset + noise_rng.normal(size=run.angles.shape) * scenario.noise
    metadata: dict[str, Any] = {
        "generator": generator,
        "provider": prototype.provider_description,
        **scenario.provenance(),
        "injected_effects": run.provenance.get("effects", []) if isinstance(run.provenance, dict) else [],
        "prototype": {
            "max_force_residual_n": float(np.max(run.force_residual)),
            "max_moment_residual_nm": float(np.max(run.moment_residual)),
            "newton_iterations_total": int(np.sum(run.newton_iterations)),
            "point_class": [str(c) for c in run.point_class],
        },
    }
    measurement = Measurement(
        point=np.arange(1, scenario.inputs.shape[0] + 1),
        time=time,
        leg=np.asarray(scenario.leg, dtype=int),
        inputs=np.asarray(scenario.inputs, dtype=float),
        angles=angles,
        extras={"temperature_c": temperature},
        metadata=metadata,
    )
    return TruthResult(measurement=measurement, run=run)


def heaviest_payload(prototype, mass: float, *, steps: int = 8) -> tuple[float, float] | None:
    """None if the prototype holds ``mass`` [kg] at zero inputs; else (lo, hi) [kg]: it finds
    an equilibrium at zero inputs under a payload of ``lo`` and none under ``hi`` (geometric
    bisection from 1 kg to ``mass``, ``steps`` halvings of the log-interval: +-5 % for 5
    decades). ``lo`` is 0 if even 1 kg fails."""
    def holds(m: float) -> bool:
        trial = dataclasses.replace(prototype, mechanism=dataclasses.replace(prototype.mechanism, payload_mass=m))
        try:
            simulate(trial, np.zeros((1, 3)))
        except NonConvergenceError:
            return False
        return True

    if holds(mass):
        return None
    lo, hi = 1.0, float(mass)
    if not holds(lo):
        return 0.0, lo
    for _ in range(steps):
        mid = float(np.sqrt(lo * hi))
        lo, hi = (mid, hi) if holds(mid) else (lo, mid)
    return lo, hi


def why_no_equilibrium(prototype, inputs: np.ndarray, message: str, nominal: MechanismParams) -> str | None:
    """What to change when the prototype found no equilibrium (``message``: the solver's,
    naming the 0-based point): a payload heavier than the mount holds (the figure found by
    ``heaviest_payload``), or inputs beyond the stroke at that point (the stroke of drive i:
    the input that alone reaches the edge of the workspace on ``nominal``'s small-deflection
    model). None when neither explains it."""
    import re

    from ..plausibility import mount_scale

    mass = float(prototype.mechanism.payload_mass)
    bounds = heaviest_payload(prototype, mass)
    if bounds is not None:
        lo, hi = bounds
        return (f"the payload of {mass:g} kg is more than this mount holds: under its weight at zero inputs the "
                f"prototype finds no equilibrium above {lo:.3g} kg (none at {hi:.3g} kg); reduce payload_mass_kg "
                f"under [mechanism] (the reference mount carries 300 kg)")
    found = re.search(r"at point (\d+)", message)
    if found is None:
        return None
    k = int(found.group(1))
    stroke = mount_scale(nominal).stroke
    ratio = np.abs(np.asarray(inputs, float)[k]) / stroke
    i = int(np.argmax(ratio))
    if ratio[i] <= 1.0:
        return None
    return (f"trajectory point {k + 1} (row {k + 2} of a trajectory file): xa{i + 1} = {inputs[k][i] * 1e3:.4g} mm is "
            f"{ratio[i]:.3g} x the stroke of D{i + 1} (+-{stroke[i] * 1e3:.3g} mm reaches the edge of the +-1/+-5/+-3 "
            f"mrad workspace on the nominal model); the prototype finds no equilibrium there: keep the inputs within "
            f"the stroke")
