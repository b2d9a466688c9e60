"""Closed-loop compensation (paper Sec. 4.1, Fig. 9) as pure loop logic.

The procedure of Fig. 9, with every piece of physics passed in as a callable so this
module knows nothing about the model or the prototype:

1. acquire the misalignment curve and 2. identify the sensitive error sources:
   ``identify() -> model`` (an opaque calibrated model);
3. compute each target's inputs through the calibrated model's inverse:
   ``inverse(model, targets (n, 3) [rad]) -> inputs (n, 3) [m]``;
4. drive the mechanism and measure: ``drive_and_measure(inputs (n, 3) [m]) -> angles (n, 3) [rad]``;
5. iterate: while a point's error exceeds the tolerance and rounds remain, correct its
   inputs with the measured error through the calibrated model's input Jacobian (with
   backtracking: a point whose error grew goes half way back to its best inputs and
   halves its later steps; each point's Jacobian is corrected by Broyden's secant update
   from what the mechanism did in the previous round),

       x_{k+1} = x_k + g J(x_k)^-1 (target - measured_k),    J = d theta / d x  [rad/m]

   (``input_jacobian(model, inputs (n, 3)) -> (n, 3, 3)`` [rad/m], [point, angle, actuator];
   g the relaxation gain, 1 = a full Newton step on the measured error), and drive again.

Every round re-drives all targets (the mechanism has memory: a target's posture depends
on what was driven before it), and corrects only the points still outside the tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

__all__ = ["LoopSettings", "LoopRound", "LoopResult", "within_tolerance", "correction_step", "broyden_update",
           "iterate", "closed_loop"]


@dataclass(frozen=True, kw_only=True)
class LoopSettings:
    """tolerance [rad]: a point is done when every angle's |error| is at most this;
    max_rounds: corrective rounds after the first (model-only) round; gain [-]: the
    fraction of the Newton correction applied per round (0 < gain <= 1)."""

    tolerance: float = 1e-6
    max_rounds: int = 8
    gain: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError(f"tolerance={self.tolerance} rad must be > 0 (e.g. 1e-6 = 1 urad)")
        if int(self.max_rounds) != self.max_rounds or self.max_rounds < 0:
            raise ValueError(f"max_rounds={self.max_rounds} must be an integer >= 0")
        if not 0.0 < self.gain <= 1.0:
            raise ValueError(f"gain={self.gain} must be in (0, 1]")


@dataclass(frozen=True, kw_only=True, eq=False)
class LoopRound:
    """One drive of all targets: inputs (n, 3) [m] driven; measured (n, 3) [rad];
    error (n, 3) [rad] = measured - target; corrected (n,) bool: the points whose inputs
    were changed for this round (all of them in round 0, the model's inverse)."""

    inputs: np.ndarray
    measured: np.ndarray
    error: np.ndarray
    corrected: np.ndarray

    @property
    def max_abs_error(self) -> np.ndarray:
        """(3,) [rad] largest |error| per angle over the points."""
        return np.max(np.abs(self.error), axis=0)


@dataclass(frozen=True, kw_only=True, eq=False)
class LoopResult:
    """targets (n, 3) [rad]; rounds: round 0 is the calibrated model's inverse (the
    paper's "after calibration"), the last one is where the loop stopped ("iterative
    approximation"); converged: every point within the tolerance in the last round."""

    targets: np.ndarray
    rounds: tuple[LoopRound, ...]
    converged: bool
    settings: LoopSettings

    @property
    def first(self) -> LoopRound:
        return self.rounds[0]

    @property
    def final(self) -> LoopRound:
        return self.rounds[-1]

    @property
    def n_corrections(self) -> int:
        return len(self.rounds) - 1


def within_tolerance(error: np.ndarray, tolerance: float) -> np.ndarray:
    """(n,) bool: every angle of the point within ``tolerance`` [rad]; error (n, 3) [rad]."""
    return np.all(np.abs(np.asarray(error)) <= tolerance, axis=-1)


def correction_step(jacobian: np.ndarray, error: np.ndarray, gain: float = 1.0) -> np.ndarray:
    """Input change (n, 3) [m] = -gain J^-1 error for jacobian (n, 3, 3) [rad/m] and
    error (n, 3) [rad] (measured - target). Raises ``ValueError`` naming a point whose
    Jacobian is singular (an actuator without effect there: the model cannot correct it)."""
    jacobian = np.asarray(jacobian, dtype=float)
    error = np.asarray(error, dtype=float)
    if jacobian.shape != error.shape + (3,):
        raise ValueError(f"jacobian must be (n, 3, 3) for errors (n, 3), got {jacobian.shape} and {error.shape}")
    try:
        return -gain * np.linalg.solve(jacobian, error[..., None])[..., 0]
    except np.linalg.LinAlgError:
        singular = np.flatnonzero(np.abs(np.linalg.det(jacobian)) == 0.0)
        point = int(singular[0]) if singular.size else -1
        raise ValueError(f"the model's input Jacobian is singular at point {point}: no input change corrects its "
                         f"error there; drop the target or recalibrate") from None


def broyden_update(jacobian: np.ndarray, dx: np.ndarray, dtheta: np.ndarray, min_change: float) -> np.ndarray:
    """Broyden's rank-one secant update of per-point Jacobians (n, 3, 3) [rad/m] with the
    last input change dx (n, 3) [m] and the measured angle change dtheta (n, 3) [rad]:
    ``J + (dtheta - J dx) dx^T / (dx^T dx)``, so J reproduces what the mechanism did.
    Points that did not move, or whose measured change is below ``min_change`` [rad] (it
    would be mostly noise), keep their Jacobian."""
    jacobian = np.array(jacobian, dtype=float)
    moved = (np.einsum("ni,ni->n", dx, dx) > 0) & (np.max(np.abs(dtheta), axis=1) > min_change)
    if np.any(moved):
        d, t, j = dx[moved], dtheta[moved], jacobian[moved]
        miss = t - np.einsum("nij,nj->ni", j, d)
        jacobian[moved] = j + miss[:, :, None] * d[:, None, :] / np.einsum("ni,ni->n", d, d)[:, None, None]
    return jacobian


def iterate(targets: np.ndarray, inputs: np.ndarray, drive_and_measure: Callable[[np.ndarray], np.ndarray],
            input_jacobian: Callable[[np.ndarray], np.ndarray], settings: LoopSettings = LoopSettings()) -> LoopResult:
    """Steps 4-5 of Fig. 9 from the first inputs (n, 3) [m] (the model's inverse).

    drive_and_measure(inputs (n, 3) [m]) -> measured (n, 3) [rad]; input_jacobian(inputs
    (n, 3) [m]) -> (n, 3, 3) [rad/m]. Stops when every point is within the tolerance or
    after ``settings.max_rounds`` corrective rounds.
    """
    targets = np.asarray(targets, dtype=float)
    x = np.array(inputs, dtype=float)
    if targets.ndim != 2 or targets.shape[1] != 3 or x.shape != targets.shape:
        raise ValueError(f"targets and inputs must both be (n, 3), got {targets.shape} and {x.shape}")
    corrected = np.ones(len(x), dtype=bool)
    rounds = []
    best_x, best_size = x.copy(), np.full(len(x), np.inf)
    gain = np.full(len(x), float(settings.gain))
    jacobian = None  # per point, from the model, then Broyden-updated by what was measured
    last_x = last_measured = None
    while True:
        measured = np.asarray(drive_and_measure(x.copy()), dtype=float)
        if measured.shape != targets.shape:
            raise ValueError(f"drive_and_measure returned shape {measured.shape}, expected {targets.shape}")
        error = measured - targets
        rounds.append(LoopRound(inputs=x.copy(), measured=measured, error=error, corrected=corrected))
        todo = ~within_tolerance(error, settings.tolerance)
        if not np.any(todo) or len(rounds) > settings.max_rounds:
            break
        if jacobian is None:
            jacobian = np.array(input_jacobian(x), dtype=float)
        else:
            jacobian = broyden_update(jacobian, x - last_x, measured - last_measured, settings.tolerance)
        # backtracking: a point whose error grew (a clearance or friction kink the model's
        # Jacobian does not see) goes back half way to its best inputs, and its later
        # steps are halved; a point that improved takes the (relaxed) Newton step
        size = np.max(np.abs(error), axis=1)
        improved = size < best_size
        best_x[improved], best_size[improved] = x[improved], size[improved]
        newton = todo & improved
        retreat = todo & ~improved
        gain[retreat] *= 0.5
        step = np.zeros_like(x)
        if np.any(newton):
            step[newton] = correction_step(jacobian[newton], error[newton], 1.0) * gain[newton, None]
        step[retreat] = 0.5 * (best_x[retreat] - x[retreat])
        last_x, last_measured = x.copy(), measured
        x = x + step
        corrected = todo
    return LoopResult(targets=targets, rounds=tuple(rounds), converged=not np.any(todo), settings=settings)


def closed_loop(targets: np.ndarray, *, identify: Callable[[], Any],
                inverse: Callable[[Any, np.ndarray], np.ndarray],
                drive_and_measure: Callable[[np.ndarray], np.ndarray],
                input_jacobian: Callable[[Any, np.ndarray], np.ndarray],
                settings: LoopSettings = LoopSettings()) -> tuple[Any, LoopResult]:
    """The whole Fig. 9 procedure: (model, ``LoopResult``).

    identify() -> model (steps 1-2); inverse(model, targets) -> inputs (n, 3) [m] (step 3);
    then ``iterate`` with ``input_jacobian(model, inputs)`` (steps 4-5).
    """
    model = identify()
    first = np.asarray(inverse(model, np.asarray(targets, dtype=float)), dtype=float)
    return model, iterate(targets, first, drive_and_measure, lambda x: input_jacobian(model, x), settings)
