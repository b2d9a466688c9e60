"""The effect library of issue #7: ids, descriptions, model terms and injectors
(docs/effects.md).

``make_injector(id, magnitude_urad, rng, mechanism=None)`` draws an injector's shape (signs,
channels, phases, time constants) from ``rng`` and scales its strength so that the linearized
angle signature on the standard trajectory of ``mechanism`` (the mount the effect is injected
into; the reference mount by default; ``effects.magnitude``) has RMS ``magnitude_urad``; ``effects_from_scenario`` turns a scenario's ``[[effects]]`` tables
into injectors. The ids outside ``EFFECT_IDS`` (``OUT_OF_LIBRARY_IDS``) have an injector
but no model term: the blind benchmark's "something else" cases.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from flexcal.geometry.params import reference_mechanism

from ..effects import injectors as inj
from . import chain
from .magnitude import estimate_magnitude, standard_setting
from .terms import TERMS, ModelTerm, path_length

__all__ = ["EFFECT_IDS", "NONE", "OUT_OF_LIBRARY_IDS", "EffectEntry", "LIBRARY", "model_term", "make_injector",
           "effects_from_scenario", "INJECTOR_TYPES"]

EFFECT_IDS = ("drift", "sensor_crosstalk", "sensor_scale", "lead_error", "friction_hysteresis",
              "coupling_windup", "large_deflection", "gravity_sag", "thermal", "creep", "step_loss",
              "sensor_settling", "air_turbulence")
NONE = "none"
OUT_OF_LIBRARY_IDS = ("sensor_interpolation",)
INJECTOR_TYPES = {
    "drift": inj.Drift, "sensor_crosstalk": inj.SensorCrosstalk, "sensor_scale": inj.SensorScale,
    "lead_error": inj.LeadError, "friction_hysteresis": inj.FrictionHysteresis,
    "coupling_windup": inj.CouplingWindup, "large_deflection": inj.LargeDeflection,
    "gravity_sag": inj.GravitySag, "thermal": inj.Thermal, "creep": inj.Creep, "step_loss": inj.StepLoss,
    "sensor_interpolation": inj.SensorInterpolation,
    "sensor_settling": chain.SensorSettling, "air_turbulence": chain.AirTurbulence,
}


@dataclass(frozen=True)
class EffectEntry:
    """id; description (one line); term (None for out-of-library effects);
    make_injector(magnitude_urad, rng) -> injector."""

    id: str
    description: str
    term: ModelTerm | None
    make_injector: Callable


def _signs(rng, n):
    return rng.choice([-1.0, 1.0], size=n)


def _shape(effect_id: str, rng: np.random.Generator, angle_gain: tuple | None = None):
    """(unit-strength injector, function factor -> injector of factor x that strength).
    angle_gain: the mount's linear gain (``injectors.reference_angle_gain``; None: the
    reference mount's), for the effects that map commands to hinge angles."""
    if effect_id == "drift":
        rate = _signs(rng, 3) * rng.uniform(0.3, 1.0, 3) * 1e-8
        curvature = rate * rng.uniform(-0.2, 0.2, 3) / 150.0  # <= 20 % more or less drift after 150 s
        steps = _signs(rng, 3) * rng.uniform(0.3, 1.0, 3) * 5e-8 * (rng.uniform() < 0.5)
        base = dict(rate=rate, curvature=curvature, reversal_step=steps)
        return lambda f: inj.Drift(**{k: f * v for k, v in base.items()})
    if effect_id == "sensor_crosstalk":
        rotation, shear = rng.normal(size=3) * 1e-3, rng.normal(size=3) * 0.5e-3
        return lambda f: inj.SensorCrosstalk(rotation=f * rotation, shear=f * shear)
    if effect_id == "sensor_scale":
        scale = _signs(rng, 3) * rng.uniform(0.3, 1.0, 3) * 1e-3
        return lambda f: inj.SensorScale(scale=f * scale)
    if effect_id == "lead_error":
        slope, amplitude = rng.normal(size=3) * 1e-4, rng.uniform(0.5, 1.0, 3) * 1e-6
        second = amplitude * rng.uniform(0.1, 0.3, 3)
        phase, phase_2 = rng.uniform(0, 2 * np.pi, 3), rng.uniform(0, 2 * np.pi, 3)
        return lambda f: inj.LeadError(slope=f * slope, amplitude=f * amplitude, second=f * second, phase=phase,
                                       phase_2=phase_2)
    if effect_id == "friction_hysteresis":
        force, coefficient = rng.uniform(50.0, 150.0, 3), rng.uniform(0.0, 0.03)
        length, exponent = rng.uniform(20e-6, 80e-6), rng.uniform(1.0, 2.0)
        return lambda f: inj.FrictionHysteresis(force=f * force, load_coefficient=f * coefficient, length=length,
                                                exponent=exponent)
    if effect_id == "coupling_windup":
        radius, preload = rng.uniform(0.5e-4, 2e-4, 3), rng.uniform(0.05, 0.2, 3)
        return lambda f: inj.CouplingWindup(torsional_stiffness=np.full(3, 300.0) / f, friction_radius=radius,
                                            preload_torque=preload)
    if effect_id == "large_deflection":
        coefficient = np.abs(rng.normal(size=6)) * 0.01  # geometric stiffening: hinges harden with bending
        return lambda f: inj.LargeDeflection(coefficient=f * coefficient, angle_gain=angle_gain)
    if effect_id == "gravity_sag":
        exponent, coefficient = rng.uniform(0.1, 0.33, 3), rng.normal(size=6) * 0.01
        return lambda f: inj.GravitySag(exponent=f * exponent, coefficient=min(f, 1.0) * coefficient)
    if effect_id == "thermal":
        expansion, lag = rng.normal(size=3) * 1e-6, rng.uniform(0.0, 30.0)
        return lambda f: inj.Thermal(expansion=f * expansion, time_constant=lag)
    if effect_id == "creep":
        compliance = _signs(rng, 1) * rng.uniform(0.5, 1.5, 3) * 1e-9
        fraction, taus = rng.uniform(0.2, 0.5), (rng.uniform(5.0, 20.0), rng.uniform(30.0, 60.0))
        return lambda f: inj.Creep(compliance=f * compliance, fraction=fraction, time_constants=taus)
    if effect_id == "sensor_settling":
        # the lag left after the 2 s dwell, per channel: tau = 0.3-1.2 s (exp(-2/tau) = 0.001-0.19);
        # the strength factor scales that remaining share, so the signature is ~linear in it
        remaining = np.exp(-2.0 / rng.uniform(0.3, 1.2)) * rng.uniform(0.7, 1.0, 3)
        window = rng.uniform(0.0, 0.5) * (rng.uniform() < 0.5)  # half the sensors average over 0-0.5 s
        return lambda f: chain.SensorSettling(time_constant=-2.0 / np.log(np.clip(f * remaining, 1e-12, 0.9)),
                                              integration_time=window)
    if effect_id == "air_turbulence":
        sd, seed = rng.uniform(0.5, 1.0, 3) * 1e-6, int(rng.integers(2**31))
        correlation = rng.uniform(30.0, 120.0)  # [s] slow refraction drift of the air path
        return lambda f: chain.AirTurbulence(sd=f * sd, correlation_time=correlation, seed=seed)
    if effect_id == "sensor_interpolation":
        amplitude, period = rng.uniform(0.5, 1.0, 3) * 1e-6, rng.uniform(0.2e-3, 0.6e-3)
        phase = rng.uniform(0, 2 * np.pi, 3)
        return lambda f: inj.SensorInterpolation(amplitude=f * amplitude, period=period, phase=phase)
    raise ValueError(f"no shape for effect {effect_id!r}")


def _step_loss(magnitude: float, rng: np.random.Generator, setting):
    """Whole steps: draw the actuator and where along its path, then the step count; if one
    step is still too large, move the event later along the path (fewer points after it)."""
    actuator = int(rng.integers(3))
    total = path_length(setting.data.inputs)[-1, actuator]
    fraction = rng.uniform(0.15, 0.85)

    def make(n, where):
        return inj.StepLoss(events=((actuator, where * total, n),))

    per_step = estimate_magnitude(make(1, fraction), setting)
    n_steps = max(1, int(round(magnitude / per_step)))
    if n_steps == 1 and per_step > magnitude:
        later = np.linspace(fraction, 0.97, 12)
        fraction = later[np.argmin([abs(estimate_magnitude(make(1, w), setting) - magnitude) for w in later])]
    return make(n_steps, fraction)


def make_injector(effect_id: str, magnitude_urad: float, rng: np.random.Generator | int | None = None, *,
                  mechanism=None):
    """An injector of ``effect_id`` whose linearized signature on the standard trajectory of
    ``mechanism`` (``MechanismParams``: the mount it goes into; None: the reference mount) has
    RMS ~``magnitude_urad`` [urad] (``effects.magnitude``); shape drawn from ``rng``."""
    if effect_id not in LIBRARY:
        raise ValueError(f"unknown effect id {effect_id!r}; known: {', '.join(LIBRARY)}")
    if not (np.isfinite(magnitude_urad) and magnitude_urad > 0):
        raise ValueError(f"magnitude_urad={magnitude_urad} must be > 0")
    rng = np.random.default_rng(rng)
    magnitude = magnitude_urad * 1e-6
    if mechanism is not None and mechanism == reference_mechanism():
        mechanism = None  # one injector per mount: the reference mount's as by default
    setting = standard_setting(mechanism)
    if effect_id == "step_loss":
        return _step_loss(magnitude, rng, setting)
    build = _shape(effect_id, rng, None if mechanism is None else inj.reference_angle_gain(mechanism))
    factor = 1.0
    for _ in range(3):  # linear in the strength for most; a few secant steps for the rest (gravity_sag)
        achieved = estimate_magnitude(build(factor), setting)
        if not achieved > 0:
            raise ValueError(f"effect {effect_id!r}: its drawn shape has no signature on the standard trajectory")
        if abs(achieved / magnitude - 1.0) < 0.01:
            break
        factor *= magnitude / achieved
    return build(factor)


def model_term(effect_id: str) -> ModelTerm:
    """The model term of a library effect; ValueError for out-of-library ids and unknown ones."""
    entry = LIBRARY.get(effect_id)
    if entry is None or entry.term is None:
        raise ValueError(f"effect {effect_id!r} has no model term; library ids: {', '.join(EFFECT_IDS)}")
    return entry.term


def _fields(kind) -> set[str]:
    return {f.name for f in dataclasses.fields(kind) if f.name != "name"}


def effects_from_scenario(entries: tuple[dict[str, Any], ...], mechanism=None) -> tuple:
    """Injectors from a scenario's ``[[effects]]`` tables.

    Each table is ``{"name": id, <field>: value, ...}`` with the injector's fields in SI
    (``effects.injectors``), or ``{"name": id, "magnitude_urad": m, "seed": s}`` for
    ``make_injector`` on ``mechanism`` (the scenario's mount; None: the reference mount).
    Raises ValueError naming an unknown id or parameter.
    """
    effects = []
    for number, entry in enumerate(entries, start=1):
        entry = dict(entry)
        name = entry.pop("name", None)
        if name not in INJECTOR_TYPES:
            raise ValueError(f"[[effects]] entry {number}: unknown effect name {name!r}; known: "
                             f"{', '.join(INJECTOR_TYPES)}")
        kind = INJECTOR_TYPES[name]
        if "magnitude_urad" in entry:
            unknown = sorted(set(entry) - {"magnitude_urad", "seed"})
            if unknown:
                raise ValueError(f"[[effects]] entry {number} ({name}): with magnitude_urad only 'seed' may be "
                                 f"given, not {unknown}")
            effects.append(make_injector(name, float(entry["magnitude_urad"]), int(entry.get("seed", 0)),
                                         mechanism=mechanism))
            continue
        unknown = sorted(set(entry) - _fields(kind))
        if unknown:
            raise ValueError(f"[[effects]] entry {number} ({name}): unknown parameter(s) {unknown}; allowed: "
                             f"{sorted(_fields(kind))} (SI units) or magnitude_urad [+ seed]")
        try:
            effects.append(kind(**entry))
        except (TypeError, ValueError) as error:
            raise ValueError(f"[[effects]] entry {number} ({name}): {error}") from None
    return tuple(effects)


_DESCRIPTIONS = {
    "drift": "sensor offset growing with time (and a step per stroke reversal)",
    "sensor_crosstalk": "sensor axes misaligned: one channel leaks into another",
    "sensor_scale": "per-channel sensor scale error",
    "lead_error": "ball-screw lead error, linear plus periodic per screw revolution",
    "friction_hysteresis": "Dahl-type rate-independent friction loop of the drives, beyond Eq. 7",
    "coupling_windup": "load-dependent lost motion of the flexible motor coupling",
    "large_deflection": "hinge geometric stiffening at large rotation",
    "gravity_sag": "load-dependent chain stiffness under the payload's weight",
    "thermal": "thermal expansion of the drives with the room temperature (column temperature_c)",
    "creep": "dwell-dependent creep of the drives under load",
    "step_loss": "lost motor steps: persistent whole-step offsets",
    "sensor_settling": "first-order sensor dynamics: the reading lags the jump of each move (time stamps)",
    "air_turbulence": "correlated (AR(1), low-frequency) air-turbulence noise on the angles",
    "sensor_interpolation": "OUT OF LIBRARY: sensor sub-division error periodic in the measured angle",
}
LIBRARY: dict[str, EffectEntry] = {
    effect_id: EffectEntry(id=effect_id, description=_DESCRIPTIONS[effect_id], term={**TERMS, **chain.CHAIN_TERMS}.get(effect_id),
                           make_injector=(lambda m, rng=None, _id=effect_id: make_injector(_id, m, rng)))
    for effect_id in EFFECT_IDS + OUT_OF_LIBRARY_IDS
}
