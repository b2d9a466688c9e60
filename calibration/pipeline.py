"""One identification of all error sources from one measured curve: MAP or free least squares.

``identify_all`` is what ``flexcal verify``, ``identify`` and ``compensate`` run by default
(``--method map``): every one of the 45 sources estimated at once with the paper's ranges as
the prior (``calibration.estimation``), the prior scale cross-validated on held-out legs, a
standard error for each source, and the base parameters (``calibration.base_parameters``)
saying which sources or combinations the data identify. ``--method free`` is the same
without a prior (bounded least squares from mid-range). The paper's method (Sobol screening
+ improved PSO) stays in ``flexcal.validation.verify``.

Values are SI throughout (``Identification.values``, ``.std``); display units are the
reports' business.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from flexcal.calibration.base_parameters import BaseParameters, base_parameters
from flexcal.calibration.estimation import (PRIOR_SCALES, CrossValidation, Estimate, choose_prior_scale, estimate,
                                            held_out_folds, uniform_prior)
from flexcal.calibration.problem import CalibrationProblem
from flexcal.model.parameters import ParameterSpace
from flexcal.model.trajectory import travel_directions

__all__ = ["IdentificationSettings", "Identification", "identify_all", "METHODS", "FREE_MAX_EVALUATIONS",
           "check_determined"]

METHODS = ("map", "free", "paper")
# free least squares on the rank-deficient 45-source problem creeps along its null space: cap
# each fit at 400 Jacobians' worth of rows (measured: the RMS no longer moves in its last digit)
FREE_MAX_EVALUATIONS = 400 * 46


@dataclass(frozen=True, kw_only=True)
class IdentificationSettings:
    """method "map" | "free"; prior_scale [x the range's spread] or None (cross-validated over
    ``scales``); noise [rad] of the sensors, or None (estimated from the residual);
    max_std [fraction of range]: a base source's data-alone standard deviation limit
    (``base_parameters``); n_folds: held-out blocks when the trajectory has fewer than 3 legs."""

    method: str = "map"
    prior_scale: float | None = None
    scales: tuple[float, ...] = PRIOR_SCALES
    noise: float | None = None
    max_std: float = 0.01
    n_folds: int = 5

    def __post_init__(self) -> None:
        if self.method not in ("map", "free"):
            raise ValueError(f"method={self.method!r} must be 'map' or 'free' here ('paper' is flexcal verify's)")
        if self.prior_scale is not None and not self.prior_scale > 0:
            raise ValueError(f"prior scale={self.prior_scale} must be > 0")
        if self.noise is not None and not self.noise > 0:
            raise ValueError(f"noise={self.noise} rad must be > 0")


@dataclass(frozen=True, kw_only=True, eq=False)
class Identification:
    """values (45,) [SI] identified; std (45,) [SI] standard errors (inf: not seen by the data
    and no prior); x_unit (45,) on the unit box; estimate: the ``Estimate``; base: the
    ``BaseParameters`` of the data Jacobian at the solution; cross_validation (or None when
    the scale was given); prior_scale used; problem: the ``CalibrationProblem`` over all
    points; fitted_angles (n, 3) [rad]; method."""

    method: str
    values: np.ndarray
    std: np.ndarray
    x_unit: np.ndarray
    estimate: Estimate
    base: BaseParameters
    cross_validation: CrossValidation | None
    prior_scale: float
    problem: CalibrationProblem
    fitted_angles: np.ndarray

    @property
    def identifiable(self) -> tuple[str, ...]:
        """The sources the data identify alone (``BaseParameters.pure``): the ones whose own
        values mean something, what the reports call identifiable."""
        return self.base.pure()


def check_determined(n_points: int, n_unknowns: int, what: str = "sources") -> None:
    """Refuse data with fewer observations (3 angles a posture) than unknowns."""
    if 3 * n_points < n_unknowns:
        raise ValueError(f"{n_points} postures give {3 * n_points} observations, fewer than the {n_unknowns} {what} "
                         f"to identify: measure at least {math.ceil(n_unknowns / 3)} postures (flexcal design makes "
                         f"a trajectory) or identify fewer sources")


def identify_all(space: ParameterSpace, inputs: np.ndarray, angles: np.ndarray, leg: np.ndarray,
                 settings: IdentificationSettings = IdentificationSettings(), *,
                 log: Callable[[str], None] = lambda _: None) -> Identification:
    """Identify every active source of ``space`` from ordered inputs (n, 3) [m] and measured
    angles (n, 3) [rad]; leg (n,) labels the trajectory's legs (held-out folds)."""
    inputs, angles = np.asarray(inputs, float), np.asarray(angles, float)
    check_determined(inputs.shape[0], space.n_params)
    directions = travel_directions(inputs)
    problem = CalibrationProblem(space=space, inputs=inputs, angles=angles, directions=directions)

    def residuals_for(points: np.ndarray):
        return CalibrationProblem(space=space, inputs=inputs[points], angles=angles[points],
                                  directions=directions[points]).residuals

    cv = None
    if settings.method == "free":
        scale = math.inf
    elif settings.prior_scale is not None:
        scale = settings.prior_scale
    else:
        folds = held_out_folds(leg, settings.n_folds)
        cv = choose_prior_scale(residuals_for, space.n_params, folds, inputs.shape[0], scales=settings.scales,
                                noise=settings.noise)
        scale = cv.best
        log(f"prior scale {scale:g} by {cv.n_folds}-fold held-out cross-validation "
            f"(held-out RMS {', '.join(f'{s:g}: {r * 1e6:.3g}' for s, r in zip(cv.scales, cv.held_out_rms))} urad)")
    prior = uniform_prior(space.n_params, scale)
    fit = estimate(problem.residuals, prior, noise=settings.noise,
                   max_evaluations=FREE_MAX_EVALUATIONS if math.isinf(scale) else None)
    base = base_parameters(fit.jacobian / fit.noise, space.names, max_std=settings.max_std)
    ranges = space.upper - space.lower
    values = space.full_values(space.from_unit(fit.x))
    std = np.zeros(len(space.parameters))
    std[space.active_indices] = fit.std * ranges
    fitted = problem.model_angles(fit.x[None])[0][0]
    return Identification(method=settings.method, values=values, std=std, x_unit=fit.x, estimate=fit, base=base,
                          cross_validation=cv, prior_scale=scale, problem=problem, fitted_angles=fitted)
