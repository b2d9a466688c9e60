"""The one identification pipeline: error sources from one measured curve, by MAP, free least
squares or the paper's improved PSO.

``identify_all`` is what ``flexcal verify``, ``identify`` and ``compensate`` run by default
(``--method map``): every one of the 45 sources estimated at once with the paper's ranges as
the prior (``calibration.estimation``), the prior scale cross-validated on held-out legs, a
standard error for each source, and the base parameters (``calibration.base_parameters``)
saying which sources or combinations the data identify. ``--method free`` is the same
without a prior (bounded least squares from mid-range). ``identify_swarm`` is the paper's
identification of chosen sources (improved PSO, least-squares polish of the swarm's good
points, Eq. 13 refinement, identifiability); the Sobol screening that chooses them for
``--method paper`` is ``flexcal.validation.runs.verify``'s first step.

Values are SI throughout (``Identification.values``, ``.std``); display units are the
reports' business.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from flexcal.calibration.base_parameters import BaseParameters, base_parameters
from flexcal.calibration.estimation import (PRIOR_SCALES, CrossValidation, Estimate, choose_prior_scale, estimate,
                                            fit_evaluations, held_out_folds, uniform_prior, with_discrepancy_bars,
                                            with_model_error)
from flexcal.calibration.identifiability import IdentifiabilityReport, identifiability
from flexcal.calibration.offset_chart import OffsetChart, offset_chart
from flexcal.calibration.polish import PolishResult, norm_sum_polish, polish_candidates
from flexcal.calibration.problem import CalibrationProblem, check_thread_count
from flexcal.calibration.profile_bars import with_profile_bars
from flexcal.calibration.pso import identify
from flexcal.calibration.pso_settings import PSOResult, PSOSettings
from flexcal.calibration.staged_start import is_consistent, second_order_form
from flexcal.model.parameters import ParameterSpace
from flexcal.model.trajectory import WORKSPACE, travel_directions

__all__ = ["IdentificationSettings", "Identification", "identify_all", "METHODS", "FREE_MAX_EVALUATIONS",
           "check_determined", "SwarmIdentification", "identify_swarm"]

METHODS = ("map", "free", "paper")
# free least squares on the rank-deficient 45-source problem creeps along its null space: cap
# each fit at 400 Jacobians' worth of rows (measured: the RMS no longer moves in its last digit)
FREE_MAX_EVALUATIONS = 400 * 46
# the estimate's own fit (and the cross-validation's reference fit, which can be it) starts again
# from its best point with a fresh budget when it stops at its budget, this many times. Measured
# (docs/calibration.md, "Session 34"): with other last bits of the consistent model, the
# noise-free table1 run's last fit stopped twice at its 100 Jacobians' worth of rows, at 0.026
# urad RMS (max 0.139) where it converges to 0.0017 (max 0.009); with 300 Jacobians' worth it
# converged (305 trust-region steps) to 0.0021 (max 0.0105). The held-out folds' fits keep their
# cap of 50 Jacobians' worth: they start at the reference fit (``choose_prior_scale``).
FINAL_BUDGET_RESTARTS = 2


@dataclass(frozen=True, kw_only=True)
class IdentificationSettings:
    """method "map" | "free"; prior_scale [x the range's spread] or None (cross-validated over
    ``scales``); noise [rad] of the sensors, or None (estimated from the residual);
    max_std [fraction of range]: a base source's data-alone standard deviation limit
    (``base_parameters``); n_folds: held-out blocks when the trajectory has fewer than 3 legs;
    profile: widen the bars of the base combinations not identified alone by their profile
    likelihood (``calibration.profile_bars``); start: values (45,) [SI] the first fit on all
    points starts from (None: the prior mean, or for a consistent space with ``staged`` the
    second-order model's estimate on the same data, ``calibration.staged_start``); with a
    cross-validation every later fit starts where that one ended (``choose_prior_scale``);
    n_threads: the model's threads per batch of candidates (``CalibrationProblem.n_threads``; the
    estimate's bits do not depend on it)."""

    method: str = "map"
    prior_scale: float | None = None
    scales: tuple[float, ...] = PRIOR_SCALES
    noise: float | None = None
    max_std: float = 0.01
    n_folds: int = 5
    profile: bool = False
    start: np.ndarray | None = None
    staged: bool = True
    n_threads: int = 1

    def __post_init__(self) -> None:
        if self.method not in ("map", "free"):
            raise ValueError(f"method={self.method!r} must be 'map' or 'free' here ('paper' is flexcal verify's)")
        if self.prior_scale is not None and not self.prior_scale > 0:
            raise ValueError(f"prior scale={self.prior_scale} must be > 0")
        if self.noise is not None and not self.noise > 0:
            raise ValueError(f"noise={self.noise} rad must be > 0")
        check_thread_count(self.n_threads)


@dataclass(frozen=True, kw_only=True, eq=False)
class Identification:
    """values (45,) [SI] identified; std (45,) [SI] standard errors (inf: not seen by the data
    and no prior); x_unit (active,) on the space's unit box; chart: the coordinates the
    estimator worked in (``calibration.offset_chart``: the mount offsets in Cartesian
    components); estimate: the ``Estimate`` in them (its x, covariance, Jacobian); base: the
    ``BaseParameters`` of the data Jacobian at the solution, over the chart's names;
    cross_validation (or None when the scale was given); prior_scale used; problem: the
    ``CalibrationProblem`` over all points (on the space's unit box); fitted_angles (n, 3)
    [rad]; method."""

    method: str
    values: np.ndarray
    std: np.ndarray
    x_unit: np.ndarray
    chart: OffsetChart
    estimate: Estimate
    base: BaseParameters
    cross_validation: CrossValidation | None
    prior_scale: float
    problem: CalibrationProblem
    fitted_angles: np.ndarray

    @property
    def identifiable(self) -> tuple[str, ...]:
        """The sources the data identify alone (``BaseParameters.pure``): the ones whose own
        values mean something, what the reports call identifiable (a mount offset's Cartesian
        component identified alone is a base parameter, not a source)."""
        names = set(self.problem.space.names)
        return tuple(n for n in self.base.pure() if n in names)


def check_determined(n_points: int, n_unknowns: int, what: str = "sources") -> None:
    """Refuse data with fewer observations (3 angles a posture) than unknowns."""
    if 3 * n_points < n_unknowns:
        raise ValueError(f"{n_points} postures give {3 * n_points} observations, fewer than the {n_unknowns} {what} "
                         f"to identify: measure at least {math.ceil(n_unknowns / 3)} postures (flexcal design makes "
                         f"a trajectory) or identify fewer sources")


def identify_all(space: ParameterSpace, inputs: np.ndarray, angles: np.ndarray, leg: np.ndarray,
                 settings: IdentificationSettings = IdentificationSettings(), *,
                 log: Callable[[str], None] = lambda _: None, on_fit: Callable[[], None] = lambda: None,
                 on_plan: Callable[[int], None] = lambda _: None,
                 model_error: np.ndarray | None = None) -> Identification:
    """Identify every active source of ``space`` from ordered inputs (n, 3) [m] and measured
    angles (n, 3) [rad]; leg (n,) labels the trajectory's legs (held-out folds). Progress:
    on_plan(number of least-squares fits) once, on_fit() after each. model_error: a model-error
    budget on these inputs the error bars carry (``calibration.discrepancy``), (K, n, 3) [rad]
    prototype - model at K mounts, or a callable values (45,) [SI] of the estimate -> such an
    array (``validation.runs.error_budget``); it does not change the estimate. With
    ``settings.profile`` the base combinations' bars carry their profile likelihood
    (``calibration.profile_bars``)."""
    inputs, angles = np.asarray(inputs, float), np.asarray(angles, float)
    check_determined(inputs.shape[0], space.n_params)
    directions = travel_directions(inputs)
    problem = CalibrationProblem(space=space, inputs=inputs, angles=angles, directions=directions,
                                 n_threads=settings.n_threads)

    # every fit runs in the chart's coordinates: the mount offsets in Cartesian components
    # (calibration.offset_chart: polar ones have a singular origin, a cut circle and a minimum
    # per direction where an offset is poorly determined)
    chart = offset_chart(space.names)

    def in_chart(residuals):
        return lambda Y: residuals(chart.to_space(Y))

    def residuals_for(points: np.ndarray):
        if np.array_equal(points, np.arange(inputs.shape[0])):  # all of them: the problem itself (its log counts)
            return in_chart(problem.residuals)
        return in_chart(CalibrationProblem(space=space, inputs=inputs[points], angles=angles[points],
                                           directions=directions[points], n_threads=settings.n_threads).residuals)

    # where every fit starts: the prior mean, or given values (e.g. an earlier measurement's
    # estimate: on a designed trajectory's large strokes the prior mean's basin can be a local
    # minimum, docs/calibration.md 11)
    start = settings.start
    if start is None and settings.staged and is_consistent(space):
        # a consistent model's basin is found from the second-order model's estimate
        # (calibration.staged_start)
        first = identify_all(second_order_form(space), inputs, angles, leg,
                             dataclasses.replace(settings, profile=False, staged=False))
        start = first.values
        log(f"start: the second-order model's estimate (fit {first.estimate.rms * 1e6:.3g} urad RMS)")
    # (the chart takes a magnitude beyond its range at the bound; a direction is periodic)
    x0 = None if start is None else np.clip(chart.from_space(space.to_unit(np.asarray(start, float)[space.active_indices])),
                                            0.0, 1.0)
    cv = None
    if settings.method == "free":
        scale = math.inf
    elif settings.prior_scale is not None:
        scale = settings.prior_scale
    else:
        folds = held_out_folds(leg, settings.n_folds)
        on_plan((settings.noise is None) + len(settings.scales) * len(folds) + 1)
        cv = choose_prior_scale(residuals_for, space.n_params, folds, inputs.shape[0], scales=settings.scales,
                                noise=settings.noise, on_fit=on_fit, x0=x0, budget_restarts=FINAL_BUDGET_RESTARTS)
        scale = cv.best
        log(f"prior scale {scale:g} by {cv.n_folds}-fold held-out cross-validation "
            f"(held-out RMS {', '.join(f'{s:g}: {r * 1e6:.3g}' for s, r in zip(cv.scales, cv.held_out_rms))} urad)")
    if cv is None:
        on_plan(1)
    prior = uniform_prior(space.n_params, scale)
    # error bars with the model's discrepancy, a process over the postures: the measured angles
    # in workspace half-widths (calibration.discrepancy)
    if cv is not None and cv.reference is not None and scale == cv.reference_scale:
        # the cross-validation's reference fit is this one (all points, this scale, the same
        # start, noise and budget): its error bars alone are left to compute
        fit = with_discrepancy_bars(cv.reference, angles / WORKSPACE)
    else:
        # from where the reference fit ended (all points, the same start) when there is one
        reached = x0 if cv is None or cv.reference is None else cv.reference.x
        fit = estimate(in_chart(problem.residuals), prior, noise=settings.noise, x0=reached,
                       max_evaluations=FREE_MAX_EVALUATIONS if math.isinf(scale) else None,
                       coordinates=angles / WORKSPACE, budget_restarts=FINAL_BUDGET_RESTARTS)
    if fit.stopped_at_budget:
        log(f"warning: the estimate's last fit stopped at its evaluation budget "
            f"({fit_evaluations(space.n_params)} residual rows, {1 + FINAL_BUDGET_RESTARTS} times), not at a minimum")
    on_fit()
    x_unit = chart.to_space(fit.x)
    values = space.full_values(space.from_unit(x_unit))
    if model_error is not None:
        samples = model_error(values) if callable(model_error) else model_error
        samples = np.asarray(samples, float)
        fit = with_model_error(fit, angles / WORKSPACE, samples.reshape(len(samples), -1))
    base = base_parameters(fit.jacobian / fit.noise, chart.names, max_std=settings.max_std)
    if settings.profile:
        alone = set(base.pure())
        rows = [row for name, row in zip(base.base, base.reported_combinations(chart.names)) if name not in alone]
        if rows:
            fit = with_profile_bars(fit, in_chart(problem.residuals), np.array(rows))
            log(f"profile likelihood of {len(rows)} base combinations: {fit.profile_bars.n_fits} constrained fits, "
                f"bars widened x{', '.join(f'{w:.3g}' for w in fit.profile_bars.widening)}")
    ranges = space.upper - space.lower
    # the sources' bars from the chart's covariance, to first order (an offset's direction at
    # zero offset: infinite); a coordinate the data and prior leave open stays infinite
    unit_std = np.sqrt(np.maximum(np.diag(chart.covariance_to_space(fit.x, fit.covariance)), 0.0))
    unit_std = np.where(np.isfinite(unit_std) & np.isfinite(fit.std), unit_std, np.inf)
    std = np.zeros(len(space.parameters))
    std[space.active_indices] = unit_std * ranges
    fitted = problem.model_angles(x_unit[None])[0][0]
    return Identification(method=settings.method, values=values, std=std, x_unit=x_unit, chart=chart, estimate=fit,
                          base=base, cross_validation=cv, prior_scale=scale, problem=problem, fitted_angles=fitted)


@dataclass(frozen=True, kw_only=True, eq=False)
class SwarmIdentification:
    """values (45,) [SI]: the chosen sources identified, the others as the space fixes them;
    std (45,) [SI]: standard errors of the chosen sources (nan: not identified, no error
    bar); x_unit: the chosen sources on the unit box; selected: their names; identifiable:
    the ones the identifiability analysis finds determined; noise [rad] and where it came
    from; pso, polish (or None), ident: what each step left; problem over the chosen sources;
    fitted_angles (n, 3) [rad]."""

    values: np.ndarray
    std: np.ndarray
    x_unit: np.ndarray
    selected: tuple[str, ...]
    identifiable: tuple[str, ...]
    noise: float
    noise_source: str
    pso: PSOResult
    polish: PolishResult | None
    ident: IdentifiabilityReport
    problem: CalibrationProblem
    fitted_angles: np.ndarray


def identify_swarm(space: ParameterSpace, inputs: np.ndarray, angles: np.ndarray, selected: tuple[str, ...],
                   pso_settings: PSOSettings = PSOSettings(), *, seed: int = 0, sensitivity: np.ndarray | None = None,
                   polish: bool = True, noise: float | None = None,
                   callback: Callable[[object], None] | None = None, n_threads: int = 1) -> SwarmIdentification:
    """The paper's identification (Sec. 3.2) of the ``selected`` sources, the others fixed as
    ``space`` holds them: the improved multi-subgroup PSO on Eq. 13 (``sensitivity``: their
    total Sobol indices, which seed the subgroups), then (``polish``) the least-squares polish
    of the swarm's distinct good points and an Eq. 13 refinement (IRLS), and the
    identifiability at the solution with ``noise`` [rad] (None: the fit RMS). callback(optimizer) after
    each PSO iteration (progress). n_threads: the model's per batch (``CalibrationProblem.n_threads``;
    the same bits at any count)."""
    inputs, angles = np.asarray(inputs, float), np.asarray(angles, float)
    check_determined(inputs.shape[0], len(selected))
    sub = space.subset(selected)
    problem = CalibrationProblem(space=sub, inputs=inputs, angles=angles, n_threads=n_threads)
    pso = identify(problem.fitness, sub.n_params, pso_settings, rng=seed, sensitivity=sensitivity, callback=callback)
    x_best, polished = pso.x_best, None
    if polish:
        # polish the swarm's distinct good points (overall, global swarm, subgroups: the
        # paper's Fig. 11 "relatively optimal solutions"), keep the best; budget: as many
        # rows as the swarm used, so the polish never more than doubles the cost
        polished, _, _ = polish_candidates(problem.residuals, pso.candidates(), max_evaluations=pso.n_evaluations,
                                           select=problem.fitness)
        if problem.fitness(polished.x[None])[0] <= pso.f_best:
            x_best = polished.x
        # the sum of squares' minimizer is not Eq. 13's when the model cannot fit exactly:
        # finish on Eq. 13 itself (IRLS), within what the polish left of its budget
        # (capped at 200 Jacobians' worth: with 45 sources an uncapped IRLS took minutes
        # of single-row calls for a last-digit gain)
        left = min(max(pso.n_evaluations - polished.n_evaluations, 4 * (sub.n_params + 1)), 200 * (sub.n_params + 1))
        refined = norm_sum_polish(problem.residuals, x_best, max_evaluations=left)
        if problem.fitness(refined.x[None])[0] < problem.fitness(x_best[None])[0]:
            x_best = refined.x
    fitted = problem.model_angles(x_best[None])[0][0]
    fit_rms = float(np.sqrt(np.mean((fitted - angles) ** 2)))
    used_noise = noise if noise else max(fit_rms, 1e-9)
    ident = identifiability(problem.residuals, x_best, sub.names, noise=used_noise)
    std = np.full(len(space.parameters), np.nan)  # sources not chosen: fixed, no error bar
    std[sub.active_indices] = ident.parameter_std * (sub.upper - sub.lower)
    return SwarmIdentification(values=sub.full_values(sub.from_unit(x_best)), std=std, x_unit=x_best,
                               selected=tuple(selected), identifiable=tuple(ident.meaningful_names),
                               noise=used_noise, noise_source="given" if noise else "fit RMS", pso=pso,
                               polish=polished, ident=ident, problem=problem, fitted_angles=fitted)
