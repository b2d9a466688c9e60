"""The standard calibration trajectory and travel directions (docs/conventions.md).

Actuators 1, 2, 3 are driven one after another, each in a reciprocal sweep
0 -> +A_i -> -A_i -> 0 while the others stay at 0. ``A_i`` is the largest amplitude that
keeps the nominal linear model (no errors, no parasitic term, no clearance) inside the
workspace (+-1 mrad theta_x, +-5 mrad theta_y, +-3 mrad theta_z), counted from the
zero-input pose (the gravity sag is a constant offset, not travel). 77 points: the start
point plus 28 + 28 + 20 on the three legs (multiples of 4, so each leg samples both
turning points exactly). The start point is labelled leg 0, the legs 1..3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexcal.geometry.params import MechanismParams

__all__ = ["Trajectory", "standard_trajectory", "travel_directions", "next_direction", "approach_directions",
           "WORKSPACE", "MIN_MOVE"]

WORKSPACE = np.array([1e-3, 5e-3, 3e-3])  # [rad] half-ranges of theta_x, theta_y, theta_z (paper Sec. 4.2)
MIN_MOVE = 1e-9  # [m] steps smaller than this are not moves (numerical jitter of computed inputs)
_LEG_WEIGHTS = (7, 7, 5)  # 28 : 28 : 20 points at the default 77


@dataclass(frozen=True, kw_only=True)
class Trajectory:
    """inputs (n, 3) [m] actuator commands; leg (n,) 0 = start point, 1..3 = leg of actuator k;
    amplitudes (3,) [m] the sweep amplitude A_i of each actuator."""

    inputs: np.ndarray
    leg: np.ndarray
    amplitudes: np.ndarray

    @property
    def n_points(self) -> int:
        return self.inputs.shape[0]

    @property
    def directions(self) -> np.ndarray:
        """(n, 3) travel directions of the sequence (``travel_directions``)."""
        return travel_directions(self.inputs)


def _leg_sizes(n_points: int) -> tuple[int, int, int]:
    units = (n_points - 1) // 4
    if n_points < 13 or (n_points - 1) % 4:
        raise ValueError(f"n_points={n_points} must be 1 + a multiple of 4 and >= 13 (each leg needs both "
                         f"turning points), e.g. 77")
    share = np.array(_LEG_WEIGHTS, dtype=float) * units / sum(_LEG_WEIGHTS)
    sizes = np.floor(share).astype(int)
    sizes = np.maximum(sizes, 1)
    while sizes.sum() < units:
        sizes[np.argmax(share - sizes)] += 1
    while sizes.sum() > units:
        sizes[np.argmax(sizes)] -= 1
    return tuple(int(4 * s) for s in sizes)


def sweep(amplitude: float, n_samples: int) -> np.ndarray:
    """Samples j = 1..n of the triangle 0 -> +A -> -A -> 0 at s = j/n, (n,) [m]."""
    s = np.arange(1, n_samples + 1) / n_samples
    return amplitude * np.where(s <= 0.25, 4.0 * s, np.where(s <= 0.75, 2.0 - 4.0 * s, 4.0 * s - 4.0))


def standard_trajectory(mech: MechanismParams | None = None, n_points: int = 77) -> Trajectory:
    """The standard trajectory of ``mech`` (the reference mechanism by default)."""
    from .assembly import mechanism_matrices
    from .parameters import parameter_space

    space = parameter_space(mech)
    matrices = mechanism_matrices(space.nominal_full, space)
    angle_gain = matrices.input_gain[0, 3:, 3:]  # d theta / d x_i [rad/m], (3 angles, 3 actuators)
    with np.errstate(divide="ignore"):
        amplitudes = np.min(np.asarray(space.mechanism.workspace, dtype=float)[:, None] / np.abs(angle_gain), axis=0)
    sizes = _leg_sizes(n_points)
    inputs = [np.zeros((1, 3))]
    legs = [np.zeros(1, dtype=int)]
    for k, size in enumerate(sizes):
        block = np.zeros((size, 3))
        block[:, k] = sweep(amplitudes[k], size)
        inputs.append(block)
        legs.append(np.full(size, k + 1))
    return Trajectory(inputs=np.concatenate(inputs), leg=np.concatenate(legs), amplitudes=amplitudes)


def travel_directions(inputs, min_move: float = MIN_MOVE) -> np.ndarray:
    """Travel direction (n, 3) in {+1, -1} of each actuator along an ordered input sequence.

    inputs (n, 3) [m]. The direction is the sign of the last move larger than ``min_move``
    [m] up to and including the point; before any move it is +1 (docs/conventions.md).
    """
    x = np.asarray(inputs, dtype=float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"inputs must have shape (n_points, 3), got {x.shape}")
    step = np.diff(x, axis=0, prepend=x[:1])
    moved = np.abs(step) > min_move
    index = np.where(moved, np.arange(x.shape[0])[:, None], -1)
    last = np.maximum.accumulate(index, axis=0)
    sign = np.sign(step[np.maximum(last, 0), np.arange(3)])
    return np.where(last >= 0, sign, 1.0)


def next_direction(direction, move, min_move: float = MIN_MOVE) -> np.ndarray:
    """The rule of ``travel_directions`` for one step: the travel direction (..., 3) after
    the command changes by ``move`` (..., 3) [m] from a state with travel direction
    ``direction`` (..., 3) in {+1, -1}: the sign of the move where it is larger than
    ``min_move`` [m], else unchanged. For code that walks a trajectory point by point."""
    move = np.asarray(move, dtype=float)
    return np.where(np.abs(move) > min_move, np.sign(move), np.asarray(direction, dtype=float))


def approach_directions(inputs, min_move: float = MIN_MOVE) -> np.ndarray:
    """Travel direction (n, 3) in {+1, -1} at each of the inputs (n, 3) [m] when each is
    reached by one straight move from the zero inputs (+1 before any move): the last
    point of ``travel_directions([0, x])`` for every row x, each row on its own."""
    x = np.asarray(inputs, dtype=float)
    return next_direction(np.ones_like(x), x, min_move)
