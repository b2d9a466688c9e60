"""Closed-form (linearized) angle signature of an injector along the standard trajectory,
for ``effects.library.make_injector`` to choose physical parameters (docs/effects.md).

The injector's hooks are called on contexts built from the nominal analytic model of one
mount (``standard_setting(mechanism)``, the reference mount by default; ``flexcal.model.forward``:
angles and chain loads at every point of that mount's standard trajectory, dwell 2 s, room
temperature of seed 0) instead of the prototype, and their outputs are mapped to angles to
first order:

- screw side: Δθ = J Δs, J the model's input Jacobian (central differences);
- stiffness side: the per-chain relative stiffness change ε_c (mean factor of the chain's
  segments minus 1) times S_c = w_c ∂θ/∂w_c, the model's angle sensitivity to the hinge
  width of chain c (a hinge's compliance terms scale like 1/w, so a width change stands
  for a stiffness change of the same relative size);
- mechanism side (``modify_mechanism``; ``modify_loaded_mechanism`` at the model's chain
  loads of the point): a changed actuator stiffness k -> k' as a nut shift N (1/k' - 1/k),
  a changed segment stiffness as above;
- sensor side: measure(θ) - θ.

The magnitude is the RMS over all points and channels of Δθ [rad]. This is an estimate
(no prototype run); the benchmark measures the achieved magnitude itself.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .terms import TermData, build_term_data
from .hooks import EffectContext, PointConditions, PointResult, room_temperature

__all__ = ["StandardSetting", "standard_setting", "estimate_signature", "estimate_magnitude"]

STANDARD_DWELL = 2.0  # [s] the scenarios' default time between points (validation/prototype/scenario.py)


@dataclass(frozen=True, kw_only=True, eq=False)
class StandardSetting:
    """A mount's standard trajectory and its nominal model along it: data (``TermData``, with
    extras temperature_c), temperature (n,) [degC], width_sensitivity (n, 6, 3) [rad] S_c,
    actuator_stiffness [N/m] of the mount's drives."""

    data: TermData
    temperature: np.ndarray
    width_sensitivity: np.ndarray
    actuator_stiffness: float


@functools.lru_cache(maxsize=4)
def standard_setting(mechanism=None) -> StandardSetting:
    """The nominal model of ``mechanism`` (``MechanismParams``; None: the reference mount) on
    its standard trajectory (computed once per mount, ~0.1 s for the reference one)."""
    from flexcal.model.forward import forward
    from flexcal.model.parameters import parameter_space
    from flexcal.model.trajectory import standard_trajectory

    space = parameter_space(mechanism)
    trajectory = standard_trajectory(space.mechanism)
    time = np.arange(trajectory.n_points) * STANDARD_DWELL
    temperature = room_temperature(time, 0)
    values = space.nominal_full
    data = build_term_data(values, trajectory.inputs, time=time, leg=trajectory.leg,
                           extras={"temperature_c": temperature}, space=space)
    relative = 1e-3  # 0.1 % width steps: linear range of the hinge formulas, far above round-off
    candidates = np.repeat(values[None], 7, axis=0)
    for c, placement in enumerate(space.mechanism.chains):
        candidates[c + 1, space.index(f"{placement.name}.w")] *= 1 + relative
    angles = forward(candidates, trajectory.inputs, data.direction, space=space).angles
    sensitivity = np.swapaxes((angles[1:] - angles[0]) / relative, 0, 1)  # (n, 6, 3)
    return StandardSetting(data=data, temperature=temperature, width_sensitivity=sensitivity,
                           actuator_stiffness=float(space.mechanism.actuator_stiffness))


def _contexts(setting: StandardSetting):
    data = setting.data
    results = [PointResult(angles=data.model_angles[k], pose=np.r_[np.zeros(3), data.model_angles[k]],
                           axial_loads=data.axial_loads[k], nut_offsets=np.zeros(3)) for k in range(len(data.time))]
    for k in range(len(data.time)):
        yield EffectContext(point_index=k, command=data.inputs[k], direction=data.direction[k],
                            previous=results[k - 1] if k else None, time=float(data.time[k]),
                            dwell=float(data.time[k] - data.time[k - 1]) if k else 0.0,
                            temperature=float(setting.temperature[k]), past_commands=data.inputs[:k + 1],
                            past_times=data.time[:k + 1], past_temperatures=setting.temperature[:k + 1],
                            history=tuple(results[:k]))


def _mechanism_change(effect, change, driving_loads: np.ndarray, actuator_stiffness: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(Δs (3,) [m], ε (6,)) of a ``modify_mechanism`` or ``modify_loaded_mechanism`` hook
    (``change``: conditions -> conditions): a changed actuator stiffness k -> k' moves each
    nut by N (1/k' - 1/k) (tension N > 0 stretches the contact); a changed segment
    stiffness is ε as for ``modify_stiffness``. Other changes have no estimate.
    actuator_stiffness [N/m]: the mount's k."""
    k_a = np.full(3, actuator_stiffness)
    marker = (np.zeros(3), np.zeros(3))
    before = PointConditions(segment_stiffness=np.ones((6, 5, 6, 6)), frame_forces=(marker,), actuator_stiffness=k_a)
    after = change(before)
    if len(after.frame_forces) != 1 or after.frame_forces[0] is not marker:
        raise ValueError(f"effect {effect.name!r} changes the frame forces: no closed-form estimate")
    shift = driving_loads * (1.0 / np.asarray(after.actuator_stiffness) - 1.0 / k_a)
    return shift, np.mean(after.segment_stiffness, axis=(1, 2, 3)) - 1.0


def estimate_signature(effect, setting: StandardSetting | None = None) -> np.ndarray:
    """Linearized angle signature (n, 3) [rad] of ``effect`` on the standard trajectory of
    ``setting``'s mount (default the reference mount's ``standard_setting()``)."""
    setting = setting or standard_setting()
    data = setting.data
    n = len(data.time)
    screw, stretch, sensor = np.zeros((n, 3)), np.zeros((n, 6)), np.zeros((n, 3))
    for k, context in enumerate(_contexts(setting)):
        if callable(getattr(effect, "modify_screw_position", None)):
            screw[k] = [effect.modify_screw_position(i, float(data.inputs[k, i]), float(data.inputs[k, i]), context)
                        - data.inputs[k, i] for i in range(3)]
        if callable(getattr(effect, "modify_stiffness", None)):
            factor = effect.modify_stiffness(np.ones((6, 5, 6, 6)), context)
            stretch[k] = np.mean(factor, axis=(1, 2, 3)) - 1.0
        changes = []
        if callable(getattr(effect, "modify_mechanism", None)):
            changes.append(lambda c, context=context: effect.modify_mechanism(c, context))
        if callable(getattr(effect, "modify_loaded_mechanism", None)):  # at the model's loads of this point
            changes.append(lambda c, k=k, context=context: effect.modify_loaded_mechanism(c, data.axial_loads[k],
                                                                                          context))
        for change in changes:
            stiffness = _mechanism_change(effect, change, data.axial_loads[k, 3:], setting.actuator_stiffness)
            screw[k] += stiffness[0]
            stretch[k] += stiffness[1]
        if callable(getattr(effect, "measure", None)):
            sensor[k] = effect.measure(data.model_angles[k].copy(), context) - data.model_angles[k]
    return (np.einsum("nai,ni->na", data.input_jacobian, screw)
            + np.einsum("nc,nca->na", stretch, setting.width_sensitivity) + sensor)


def estimate_magnitude(effect, setting: StandardSetting | None = None) -> float:
    """RMS over points and channels of ``estimate_signature`` [rad]."""
    return float(np.sqrt(np.mean(estimate_signature(effect, setting) ** 2)))
