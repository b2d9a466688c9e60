"""Model-side terms of the effect library (issue #7): few-parameter angle increments the
diagnosis adds to the calibrated model (docs/effects.md).

A ``ModelTerm`` maps parameters (k,) to an angle increment (n, 3) [rad] added to the
calibrated model's angles, from the ``TermData`` of a measurement (commands, time, travel
directions, the baseline model's angles, loads and input Jacobian, optional columns).
Every term is zero at zero parameters (= effect absent). Screw-side terms give a screw
displacement Δx (n, 3) [m] per actuator and map it to angles with the input Jacobian,
``Δθ = J Δx``; sensor-side terms act on the model angles; ``thermal`` on the
``temperature_c`` column. The prototype's injectors (``effects.injectors``) are richer
than these formulas, so a fit of a term to its injector's signature is a real test.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable

import numpy as np

from .hooks import REFERENCE_TEMPERATURE_C

__all__ = ["TermData", "ModelTerm", "build_term_data", "TERMS", "reversal_counts", "travel_since_reversal",
           "path_length", "path_fraction", "time_rate", "SCREW_LEAD", "TERM_DAHL_LENGTH", "TERM_CREEP_TIME"]

SCREW_LEAD = 1e-3  # [m/rev] ball-screw lead of D1..D3 (the code has none; issue #7 guidance)
TERM_DAHL_LENGTH = 50e-6  # [m] fixed transition length of the friction term (injectors draw 20..80 um)
TERM_CREEP_TIME = 20.0  # [s] the creep term's relaxation time at zero parameters (free: x exp(log_tau))
CREEP_LOG_TAU_LIMIT = 5.0  # [-] |ln(tau / TERM_CREEP_TIME)| is clipped here: tau in 0.13..3000 s, no overflow
ANGLE_SCALE = 1e-3  # [rad] the frame rotates by a few mrad on the standard trajectory
LOAD_SCALE = 1e3  # [N] chain loads are ~1 kN (docs/prototype.md): per-newton parameters are scaled by it


@dataclass(frozen=True, kw_only=True, eq=False)
class TermData:
    """What a term sees of a measurement (n points).

    inputs (n, 3) [m] commands D1..D3; time (n,) [s]; leg (n,) int; direction (n, 3) +1/-1
    (``model.trajectory.travel_directions``); model_angles (n, 3) [rad] of the calibrated
    baseline model; axial_loads (n, 6) [N] its chain loads, tension +, L1..L3, D1..D3;
    input_jacobian (n, 3, 3) [rad/m] d(angle a)/d(actuator i) as [point, a, i]; extras:
    optional columns by CSV name (file units), e.g. ``temperature_c``.
    """

    inputs: np.ndarray
    time: np.ndarray
    leg: np.ndarray
    direction: np.ndarray
    model_angles: np.ndarray
    axial_loads: np.ndarray
    input_jacobian: np.ndarray
    extras: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = np.shape(self.inputs)[0]
        for name, shape in (("inputs", (n, 3)), ("time", (n,)), ("leg", (n,)), ("direction", (n, 3)),
                            ("model_angles", (n, 3)), ("axial_loads", (n, 6)), ("input_jacobian", (n, 3, 3))):
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"TermData.{name} has shape {np.shape(getattr(self, name))}, expected {shape}")

    @cached_property
    def inputs_path_fraction(self) -> tuple[np.ndarray, np.ndarray]:
        """``path_fraction(inputs)`` (read-only arrays), computed once per data: the diagnosis
        fits step_loss by variable projection and evaluates it ~10^5 times on the same data,
        where recomputing it was 22 % of a diagnosis (measured 2026-11-28, docs/testing.md)."""
        fraction, move = path_fraction(self.inputs)
        fraction.setflags(write=False)
        move.setflags(write=False)
        return fraction, move


@dataclass(frozen=True, kw_only=True, eq=False)
class ModelTerm:
    """A model term: ``evaluate(params (k,), data) -> (n, 3) [rad]``, zero at zero params.

    scale (k,): typical magnitude of each parameter (x_scale of a fit); requires: extras
    columns the term needs (the diagnosis skips it when one is missing); starts: None, or
    ``starts(data) -> (s, k)`` [units of scale] candidate starting points of a nonlinear fit
    (the diagnosis refines the lowest-cost few: ``which.fit_terms``), for a term whose cost
    has many local minima (a step's place along the path).
    """

    id: str
    parameter_names: tuple[str, ...]
    parameter_units: tuple[str, ...]
    scale: np.ndarray
    evaluate: Callable[[np.ndarray, TermData], np.ndarray]
    requires: tuple[str, ...] = ()
    starts: Callable[[TermData], np.ndarray] | None = None

    def __post_init__(self) -> None:
        k = len(self.parameter_names)
        if len(self.parameter_units) != k or np.shape(self.scale) != (k,):
            raise ValueError(f"term {self.id!r}: {k} parameter names need {k} units and scales")

    @property
    def n_params(self) -> int:
        return len(self.parameter_names)


def build_term_data(values: np.ndarray, inputs: np.ndarray, *, time: np.ndarray, leg: np.ndarray | None = None,
                    extras: dict | None = None, model_angles: np.ndarray | None = None, space=None,
                    step: float = 1e-7) -> TermData:
    """``TermData`` from the analytic model at parameters ``values`` (45,) [SI].

    inputs (n, 3) [m]; time (n,) [s]; model_angles (n, 3) [rad] replaces the model's angles
    if given (e.g. a measured baseline). The input Jacobian is a central difference of
    ``flexcal.model.forward`` with step ``step`` [m] (1e-7 m: ~1e-4 of the stroke, far
    above the model's 1e-13 m fixed-point tolerance) at the trajectory's travel directions.
    """
    from flexcal.model.forward import forward
    from flexcal.model.trajectory import travel_directions

    x = np.asarray(inputs, dtype=float)
    n = x.shape[0]
    direction = travel_directions(x)
    base = forward(values, x, direction, space=space)
    jacobian = np.zeros((n, 3, 3))
    for i in range(3):
        shift = np.zeros(3)
        shift[i] = step
        plus = forward(values, x + shift, direction, space=space).angles[0]
        minus = forward(values, x - shift, direction, space=space).angles[0]
        jacobian[:, :, i] = (plus - minus) / (2 * step)
    angles = base.angles[0] if model_angles is None else np.asarray(model_angles, dtype=float)
    return TermData(inputs=x, time=np.asarray(time, dtype=float),
                    leg=np.zeros(n, int) if leg is None else np.asarray(leg, dtype=int), direction=direction,
                    model_angles=angles, axial_loads=base.axial_loads[0], input_jacobian=jacobian,
                    extras=dict(extras or {}))


# ---------------------------------------------------------------- path features (pure, (n, 3))

def reversal_counts(direction: np.ndarray) -> np.ndarray:
    """(n, 3) number of travel-direction reversals of each actuator up to each point."""
    d = np.asarray(direction, dtype=float)
    flips = np.vstack([np.zeros((1, d.shape[1])), (np.diff(d, axis=0) != 0)])
    return np.cumsum(flips, axis=0)


def path_length(inputs: np.ndarray) -> np.ndarray:
    """(n, 3) [m] distance travelled by each actuator up to each point (sum of |steps|)."""
    x = np.asarray(inputs, dtype=float)
    return np.cumsum(np.abs(np.diff(x, axis=0, prepend=x[:1])), axis=0)


def path_fraction(inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s (n, 3), move (3,)): each actuator's travelled path as a fraction of its whole path
    [-] (0 for one that never moves) and its median nonzero move in that unit [-]."""
    path = path_length(inputs)
    fraction = path / np.where(path[-1] > 0, path[-1], 1.0)
    steps = np.diff(fraction, axis=0)
    move = np.array([np.median(c[c > 1e-12]) if np.any(c > 1e-12) else 1.0 for c in steps.T])
    return fraction, move


def travel_since_reversal(inputs: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(n, 3) [m] distance each actuator travelled since its last reversal (or the start)."""
    path = path_length(inputs)
    count = reversal_counts(direction)
    out = np.zeros_like(path)
    for i in range(path.shape[1]):
        starts = np.flatnonzero(np.diff(count[:, i], prepend=0.0) > 0)
        # a reversal at point k means the move k-1 -> k went the new way: it started at k-1
        origin = np.zeros(path.shape[0])
        for k in starts:
            origin[k:] = path[k - 1, i]
        out[:, i] = path[:, i] - origin
    return out


def dahl_state(inputs: np.ndarray, length: float) -> np.ndarray:
    """(n, 3) normalized Dahl friction state z in (-1, 1) of each actuator, starting at 0.

    Exact solution of dz/dx = (1 - z sgn(dx)) / length over each step (rate-independent).
    """
    x = np.asarray(inputs, dtype=float)
    z = np.zeros_like(x)
    for k in range(1, x.shape[0]):
        dx = x[k] - x[k - 1]
        s = np.sign(dx)
        z[k] = s + (z[k - 1] - s) * np.exp(-np.abs(dx) / length)
    return z


def relaxed(series: np.ndarray, time: np.ndarray, time_constant: float) -> np.ndarray:
    """(n, m) first-order lag of ``series`` (n, m) held piecewise constant between the points.

    y_0 = series_0 (in equilibrium at the start); over the dwell t_k - t_{k-1} the input is
    series_{k-1}: y_k = series_{k-1} + (y_{k-1} - series_{k-1}) exp(-dwell / tau).
    """
    from ._recurrences import lag

    decay = np.exp(-np.diff(np.asarray(time, dtype=float)) / time_constant)
    return lag(np.ascontiguousarray(series, dtype=float), decay)  # the loop, compiled


# ---------------------------------------------------------------- the terms

def time_rate(values: np.ndarray, time: np.ndarray) -> np.ndarray:
    """(n,) d values / dt [unit/s] of a series (n,) at times (n,) [s], non-decreasing: the
    gradient over the distinct time stamps, points sharing a stamp (two readings in one
    second) sharing their mean value's rate; 0 with fewer than two distinct stamps. (np.gradient
    on the raw times divided by the zero step: RuntimeWarnings and NaN reached the diagnosis.)"""
    unique, inverse = np.unique(np.asarray(time, dtype=float), return_inverse=True)
    if unique.size < 2:
        return np.zeros(np.shape(values))
    mean = np.bincount(inverse, weights=np.asarray(values, dtype=float)) / np.bincount(inverse)
    return np.gradient(mean, unique)[inverse]


def _to_angles(dx: np.ndarray, data: TermData) -> np.ndarray:
    """Screw displacements (n, 3) [m] -> angle increments (n, 3) [rad] (Δθ = J Δx)."""
    return np.einsum("nai,ni->na", data.input_jacobian, dx)


def _drift(p, data):  # rate (3) [rad/s], step per reversal (3) [rad]
    n_reversals = reversal_counts(data.direction).sum(axis=1)
    return np.outer(data.time - data.time[0], p[:3]) + np.outer(n_reversals, p[3:6])


_OFF_DIAGONAL = [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]


def _crosstalk(p, data):  # C_ab (6) [rad/rad], a != b
    matrix = np.zeros((3, 3))
    for value, (a, b) in zip(p, _OFF_DIAGONAL):
        matrix[a, b] = value
    return data.model_angles @ matrix.T


def _scale(p, data):  # s (3) [-]
    return data.model_angles * p[:3]


def _lead(p, data):  # per actuator i: slope a_i [-], sine b_i [m], cosine c_i [m]
    x = data.inputs
    phase = 2 * np.pi * x / SCREW_LEAD
    a, b, c = p[0:3], p[3:6], p[6:9]
    return _to_angles(a * x + b * np.sin(phase) + c * (np.cos(phase) - 1.0), data)


def _friction(p, data):  # lag h_i [m] times the Dahl state of the command
    return _to_angles(-p[:3] * dahl_state(data.inputs, TERM_DAHL_LENGTH), data)


def _windup(p, data):  # w_i [m/kN] against travel x |N|, c_i [m/kN] with N
    load = data.axial_loads[:, 3:] / LOAD_SCALE
    return _to_angles(-p[:3] * data.direction * np.abs(load) + p[3:6] * load, data)


def _large_deflection(p, data):  # q_a [rad] per channel and r_i [m/kN] per drive, times (|theta| / 1 mrad)^2
    bend = np.sum(data.model_angles**2, axis=1, keepdims=True) / ANGLE_SCALE**2
    return p[:3] * bend + _to_angles(p[3:6] * bend * data.axial_loads[:, 3:] / LOAD_SCALE, data)


def _gravity_sag(p, data):  # g_i [m/kN^2] of N_i^2 per driving chain, h [rad/kN] of the summed load per channel
    load = data.axial_loads / LOAD_SCALE
    return _to_angles(p[:3] * load[:, 3:] ** 2, data) + np.outer(load[:, :3].sum(axis=1), p[3:6])


def _thermal(p, data):  # k_a [rad/K] of T - T_ref, l_a [rad s/K] of dT/dt per channel (a lag ~ -tau dT/dt)
    temperature = np.asarray(data.extras["temperature_c"], dtype=float)
    rate = time_rate(temperature, data.time)
    return np.outer(temperature - REFERENCE_TEMPERATURE_C, p[:3]) + np.outer(rate, p[3:6])


def _creep(p, data):  # kappa_i [m/kN] of the relaxed change of the driving load; ln(tau / 20 s) [-]
    tau = TERM_CREEP_TIME * np.exp(np.clip(p[3], -CREEP_LOG_TAU_LIMIT, CREEP_LOG_TAU_LIMIT))
    load = data.axial_loads[:, 3:] / LOAD_SCALE
    return _to_angles(p[:3] * (relaxed(load, data.time, tau) - load[0]), data)


def _step_loss(p, data):  # lost motion a_i [m] (3); place c_i = 0.5 + p_{3+i} [path fraction] (3)
    """A persistent step of a_i in actuator i's screw position once its travelled path
    fraction s passes c_i, as a one-move ramp clip((s - c_i) / move_i, 0, 1): c_i between two
    moves interpolates between a step at the one and at the next, so the fit can slide the
    step along the path (nonlinear in c_i; the diagnosis fits it by variable projection)."""
    fraction, move = data.inputs_path_fraction
    return _to_angles(p[:3] * np.clip((fraction - (0.5 + p[3:6])) / move, 0.0, 1.0), data)


STEP_PLACE_SCALE = 0.25  # [path fraction] the scale of step_loss's place parameters


def _step_loss_starts(data):
    """(s, 6) [units of scale]: a step of +-1 scale (5 um) in one drive, placed right after
    each distinct point of its path (all three places there). The cost over a place has a
    local minimum at nearly every move (the ramp is one move wide), so a fit started at a
    fixed place often stops at the wrong one: measured on the README design (FEM, step_loss
    3x seed 0), leaving leg 5 out, the five fixed starts reached a training chi2 of 808 and a
    held-out one of 2283 where the place of least cost gives 354 and 26 (docs/diagnosis.md)."""
    fraction, _ = data.inputs_path_fraction
    blocks = []
    for drive in range(3):
        places = np.unique(fraction[:, drive])[:-1]
        block = np.zeros((2 * places.size, 6))
        block[:, drive] = np.tile([1.0, -1.0], places.size)
        block[:, 3:] = np.repeat((places - 0.5) / STEP_PLACE_SCALE, 2)[:, None]  # place c_i = 0.5 + p_{3+i}
        blocks.append(block)
    return np.concatenate(blocks)


def _term(effect_id, names, units, scale, evaluate, requires=(), starts=None):
    def checked(params, data, _n=len(names), _f=evaluate, _id=effect_id):
        params = np.asarray(params, dtype=float)
        if params.shape != (_n,):
            raise ValueError(f"term {_id!r} takes {_n} parameters, got shape {params.shape}")
        return _f(params, data)

    return ModelTerm(id=effect_id, parameter_names=tuple(names), parameter_units=tuple(units),
                     scale=np.asarray(scale, dtype=float), evaluate=checked, requires=tuple(requires),
                     starts=starts)


_XYZ, _D = ("x", "y", "z"), ("D1", "D2", "D3")
TERMS: dict[str, ModelTerm] = {t.id: t for t in (
    _term("drift", [f"rate_{c}" for c in _XYZ] + [f"reversal_step_{c}" for c in _XYZ],
          ["rad/s"] * 3 + ["rad"] * 3, [1e-7] * 3 + [5e-6] * 3, _drift),
    _term("sensor_crosstalk", [f"c_{'xyz'[a]}{'xyz'[b]}" for a, b in _OFF_DIAGONAL], ["rad/rad"] * 6, [5e-3] * 6,
          _crosstalk),
    _term("sensor_scale", [f"scale_{c}" for c in _XYZ], ["-"] * 3, [5e-3] * 3, _scale),
    _term("lead_error", [f"{k}_{d}" for k in ("slope", "sin", "cos") for d in _D], ["-"] * 3 + ["m"] * 6,
          [1e-3] * 3 + [1e-6] * 6, _lead),
    _term("friction_hysteresis", [f"lag_{d}" for d in _D], ["m"] * 3, [1e-6] * 3, _friction),
    _term("coupling_windup", [f"windup_{d}" for d in _D] + [f"compliance_{d}" for d in _D], ["m/kN"] * 6,
          [1e-6] * 6, _windup),
    _term("large_deflection", [f"bend_{c}" for c in _XYZ] + [f"bend_load_{d}" for d in _D],
          ["rad"] * 3 + ["m/kN"] * 3, [1e-6] * 6, _large_deflection),
    _term("gravity_sag", [f"square_{d}" for d in _D] + [f"load_{c}" for c in _XYZ], ["m/kN^2"] * 3 + ["rad/kN"] * 3,
          [1e-6] * 3 + [1e-6] * 3, _gravity_sag),
    _term("thermal", [f"k_{c}" for c in _XYZ] + [f"lag_{c}" for c in _XYZ], ["rad/K"] * 3 + ["rad s/K"] * 3,
          [1e-5] * 3 + [1e-4] * 3, _thermal, requires=("temperature_c",)),
    # ln(tau/20 s) at +-1 scale (the fit's extra starts) is tau = 7.4 s and 54 s: the injectors' 5-60 s
    _term("creep", [f"creep_{d}" for d in _D] + ["log_time_constant"], ["m/kN"] * 3 + ["ln(tau/20 s)"],
          [1e-6] * 3 + [1.0], _creep),
    # lost motion at the 5 um motor step; place at +-1 scale (the fit's extra starts) 0.25 and 0.75 of the path
    _term("step_loss", [f"lost_{d}" for d in _D] + [f"place_{d}" for d in _D], ["m"] * 3 + ["-"] * 3,
          [5e-6] * 3 + [STEP_PLACE_SCALE] * 3, _step_loss, starts=_step_loss_starts),
)}
