"""The identification problem: the analytic model against a measured curve (paper Eq. 11, 13).

``CalibrationProblem`` binds a parameter space (the sources to identify, the others
fixed), the ordered inputs and the measured angles. Its batched functions take points
of the unit hypercube (Eq. 9), evaluate the model once for the whole batch and count
every posture evaluation:

- ``fitness(eta (n, d)) -> (n,)``: Eq. 13, the mean over points of ``||θ_i − θ_i,meas||_2`` [rad];
- ``residuals(eta (n, d)) -> (n, 3 n_points)``: the stacked angle errors [rad] (least squares);
- ``deviation_from_ideal(eta)``: Eq. 11 for the Sobol screening, overall and per angle.

Model failures (a point that does not converge) become a large finite penalty in the
fitness rather than a NaN, and are counted (``n_failures``), so one bad particle never
stops a swarm.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexcal.model.forward import ConvergenceError, forward, ideal_angles
from flexcal.model.parameters import ParameterSpace
from flexcal.model.trajectory import travel_directions

__all__ = ["CalibrationProblem", "EvaluationLog", "check_thread_count"]


def check_thread_count(value, name: str = "n_threads") -> None:
    """The model's thread count per batch (``model.forward``'s n_threads), as every setting that
    carries one takes it: an integer >= 1, else ValueError naming ``name``."""
    if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
        raise ValueError(f"{name}={value!r} must be an integer >= 1")

FAILURE_PENALTY = 1.0  # [rad] fitness of a candidate whose model did not converge (~1000x any real misfit)


@dataclass
class EvaluationLog:
    """Mutable counters: model candidates, posture evaluations, failed candidates."""

    n_candidates: int = 0
    n_postures: int = 0
    n_failures: int = 0


@dataclass(frozen=True, kw_only=True, eq=False)
class CalibrationProblem:
    """space: the parameter space (active = identified); inputs (n, 3) [m] ordered;
    angles (n, 3) [rad] measured; directions (n, 3) default from the inputs;
    clearance_mode of the model; chunk: candidates per model call (memory); n_threads: the
    model's threads per call (``model.forward``: a batch's compiled solve over them, the same
    bits at any count)."""

    space: ParameterSpace
    inputs: np.ndarray
    angles: np.ndarray
    directions: np.ndarray | None = None
    clearance_mode: str = "force_only"
    chunk: int = 2048
    n_threads: int = 1
    log: EvaluationLog = field(default_factory=EvaluationLog)

    def __post_init__(self) -> None:
        check_thread_count(self.n_threads)
        inputs = np.asarray(self.inputs, dtype=float)
        angles = np.asarray(self.angles, dtype=float)
        if inputs.ndim != 2 or inputs.shape[1] != 3 or angles.shape != inputs.shape:
            raise ValueError(f"inputs and angles must both be (n_points, 3), got {inputs.shape} and {angles.shape}")
        directions = travel_directions(inputs) if self.directions is None else np.asarray(self.directions, float)
        object.__setattr__(self, "inputs", inputs)
        object.__setattr__(self, "angles", angles)
        object.__setattr__(self, "directions", directions)

    @property
    def n_dims(self) -> int:
        return self.space.n_params

    @property
    def n_points(self) -> int:
        return self.inputs.shape[0]

    def model_angles(self, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(angles (n, n_points, 3) [rad], ok (n,) bool) for unit-cube points eta (n, d)."""
        eta = np.atleast_2d(np.asarray(eta, dtype=float))
        values = self.space.full_values(self.space.from_unit(np.clip(eta, 0.0, 1.0)))
        out = np.zeros((values.shape[0], self.n_points, 3))
        ok = np.ones(values.shape[0], dtype=bool)
        for start in range(0, values.shape[0], self.chunk):
            block = slice(start, start + self.chunk)
            out[block], ok[block] = self._angles_block(values[block])
        self.log.n_candidates += values.shape[0]
        self.log.n_postures += values.shape[0] * self.n_points
        self.log.n_failures += int(np.count_nonzero(~ok))
        return out, ok

    def _angles_block(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        try:
            result = forward(values, self.inputs, self.directions, space=self.space,
                             clearance_mode=self.clearance_mode, n_threads=self.n_threads)
            return result.angles, np.ones(values.shape[0], dtype=bool)
        except ConvergenceError:
            if values.shape[0] == 1:
                return np.zeros((1, self.n_points, 3)), np.zeros(1, dtype=bool)
            half = values.shape[0] // 2  # isolate the failing candidates by bisection
            a, ok_a = self._angles_block(values[:half])
            b, ok_b = self._angles_block(values[half:])
            return np.concatenate([a, b]), np.concatenate([ok_a, ok_b])

    def fitness(self, eta: np.ndarray) -> np.ndarray:
        """Eq. 13: mean over points of the Euclidean norm of the angle error, (n,) [rad]."""
        angles, ok = self.model_angles(eta)
        value = np.linalg.norm(angles - self.angles, axis=-1).mean(axis=-1)
        return np.where(ok, value, FAILURE_PENALTY)

    def residuals(self, eta: np.ndarray) -> np.ndarray:
        """Angle errors (n, 3 n_points) [rad], points major (θx, θy, θz of point 1, ...)."""
        angles, ok = self.model_angles(eta)
        residual = (angles - self.angles).reshape(angles.shape[0], -1)
        return np.where(ok[:, None], residual, FAILURE_PENALTY)

    def deviation_from_ideal(self, eta: np.ndarray) -> np.ndarray:
        """Eq. 11 outputs (n, 4): mean ||θ − θ_ideal|| and the mean |Δθx|, |Δθy|, |Δθz| [rad]
        against the ideal small-deflection model at the same inputs (Sobol screening)."""
        angles, ok = self.model_angles(eta)
        delta = angles - ideal_angles(self.inputs, self.space)[None]
        out = np.concatenate([np.linalg.norm(delta, axis=-1).mean(axis=-1)[:, None],
                              np.abs(delta).mean(axis=1)], axis=1)
        return np.where(ok[:, None], out, np.nan)
