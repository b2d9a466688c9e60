"""The Section 3.3 regression run: misalignment curves -> identification -> accuracy
report against the preset errors and the paper's Table 1.

Identification, ``VerifySettings.method``:

- "map" (default): all 45 sources at once, the paper's ranges as a Gaussian prior whose scale
  is cross-validated on held-out legs, a standard error for each source and the base
  parameters the data identify (``flexcal.calibration.pipeline.identify_all``);
- "free": the same without a prior (bounded least squares);
- "paper": the paper's Sobol screening + improved PSO, described below.

Every identified value carries a standard error (the paper method: the Gauss-Newton one
of the PSO's subset; screened-out sources have none), and with synthetic data its z-score.
Table 1 rows that the mount cannot show (a drive compressed at every posture of the
trajectory: its clearance never opens) are reported as "not observable on this mount", with
the reason, never as a miss.

Screening (paper Sec. 3.1, Eq. 11-12): total Sobol indices of the model's deviation from
the ideal small-deflection model, overall and per angle, over all 45 sources (SALib,
N = 512: the paper's 500 is not a power of two). Sources whose total index reaches
``sobol_threshold`` on any output are identified, plus the nine drive sources of Table 1
(initial positions, clearances, hysteresis coefficients), which are identified whatever
their index because the report must give them; the rest stay at nominal.

Identification (Sec. 3.2, Eq. 13): the improved multi-subgroup PSO with the paper's
settings on the selected sources (per-dimension speed limits from the indices), then
optionally a bounded least-squares polish from its best candidates. Identifiability at
the solution (scaled Jacobian SVD, rank, condition number, confounded groups) says which
identified values mean something.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from flexcal.calibration.pipeline import IdentificationSettings, identify_all, identify_swarm
from flexcal.calibration.problem import CalibrationProblem
from flexcal.calibration.sensitivity import select_parameters, sobol_indices
from flexcal.model.parameters import DRIVE_SOURCE_NAMES, ParameterSpace

from ..blas_threads import single_blas_thread
from ..executor import usable_cores
from ..progress import progress_bar, with_progress
from ..measurements import Measurement
from .form_floor import TruthCurve, model_form_floor, not_available
from .settings import VerifySettings

__all__ = ["VerifySettings", "VerifyResult", "run_verify", "PAPER_TABLE1", "PAPER_DRIVE_FIGURES"]

# Paper Table 1 / Sec. 3.3 figures: maximum identification errors and the orientation fit
PAPER_TABLE1 = {
    "initial_position_max_abs_error_um": 2.7,
    "clearance_max_abs_error_mm": 0.02,
    "hysteresis_max_rel_error_pct": 1.3,
    "other_max_rel_error_pct": 10.0,
    "orientation_fit_max_urad": 0.015,
}
# each drive symbol's Table 1 row, and its figure in Table 1's unit: x0 um, CL mm, mu % relative to its value
DRIVE_ROWS = {"x0": "initial_position_max_abs_error_um", "CL": "clearance_max_abs_error_mm",
              "mu": "hysteresis_max_rel_error_pct"}
PAPER_DRIVE_FIGURES = {symbol: PAPER_TABLE1[key] for symbol, key in DRIVE_ROWS.items()}
OUTPUTS = ("overall", "theta_x", "theta_y", "theta_z")


@dataclass(frozen=True, kw_only=True, eq=False)
class VerifyResult:
    report: dict[str, Any]
    values: np.ndarray
    std: np.ndarray
    sobol: Any
    pso: Any
    polish: Any
    identifiability: Any
    identification: Any
    problem: CalibrationProblem
    fitted_angles: np.ndarray
    ideal_angles: np.ndarray
    point_class: tuple[str, ...]


def _parameter_rows(space: ParameterSpace, identified: np.ndarray, presets: np.ndarray | None,
                    selected: tuple[str, ...], meaningful: set[str], *, std: np.ndarray | None = None,
                    unobservable: dict[str, str] | None = None,
                    undetermined: dict[str, str] | None = None) -> list[dict[str, Any]]:
    """One row per source, display units: identified value, standard error (None where the
    source was not identified), and with presets the errors and the z-score (error / std; none
    for an offset direction the data do not determine, ``_undetermined``: the row's
    ``undetermined`` says why)."""
    undetermined = undetermined or {}
    rows = []
    for i, (p, value) in enumerate(zip(space.parameters, identified)):
        s = p.display_scale
        se = None if std is None or not np.isfinite(std[i]) or p.name not in selected else float(std[i])
        row = {"name": p.name, "unit": p.display_unit, "nominal": p.nominal * s, "identified": value * s,
               "std_error": None if se is None else se * s, "was_identified": p.name in selected,
               "identifiable": p.name in meaningful,
               "observable": (unobservable or {}).get(p.name, "yes")}
        if presets is not None:
            preset = presets[space.index(p.name)]
            row["preset"] = preset * s
            row["abs_error"] = abs(value - preset) * s
            row["rel_error"] = abs(value - preset) / abs(preset) if preset != 0 else None
            row["error_of_range"] = abs(value - preset) / (p.upper - p.lower)
            row["z_score"] = (value - preset) / se if se and p.name not in undetermined else None
        if p.name in undetermined:
            row["undetermined"] = undetermined[p.name]
        rows.append(row)
    return rows


def _figures(rows: list[dict[str, Any]], keep) -> dict[str, float]:
    """The Table 1 figures over the rows ``keep(row)`` accepts (nan where none is left)."""
    def worst(names, value):
        found = [value(r) for r in rows if r["name"] in names and keep(r)]
        return max(found, default=float("nan"))

    drive = lambda symbol: {f"D{i}.{symbol}" for i in (1, 2, 3)}  # noqa: E731
    others = {r["name"] for r in rows if r["name"] not in DRIVE_SOURCE_NAMES and r["was_identified"]
              and r["rel_error"] is not None}  # screened-out sources stay at nominal
    return {
        "initial_position_max_abs_error_um": worst(drive("x0"), lambda r: r["abs_error"] * 1e3),
        "clearance_max_abs_error_mm": worst(drive("CL"), lambda r: r["abs_error"]),
        "hysteresis_max_rel_error_pct": worst(drive("mu"), lambda r: 100 * r["rel_error"]),
        "other_max_rel_error_pct": worst(others, lambda r: 100 * r["rel_error"]),
    }


def _paper_comparison(rows: list[dict[str, Any]], fit_max_urad: float,
                      unobservable: dict[str, str] | None = None) -> list[dict[str, Any]]:
    """Each paper figure beside ours twice: over every identified parameter ("ours") and
    over those the identifiability analysis calls meaningful ("ours_identifiable"); the
    parameters left out of the second are named, so an unidentifiable value is never
    reported as luck. Sources the mount cannot show (``unobservable``: their reason) are
    left out of both and named with the reason; a row left with none says so instead of a
    miss."""
    unobservable = unobservable or {}
    shown = [r for r in rows if r["name"] not in unobservable]
    every = _figures(shown, lambda r: True) | {"orientation_fit_max_urad": fit_max_urad}
    meaningful = _figures(shown, lambda r: r["identifiable"]) | {"orientation_fit_max_urad": fit_max_urad}
    groups = {key: symbol for symbol, key in DRIVE_ROWS.items()}
    out = []
    for key, paper in PAPER_TABLE1.items():
        symbol = groups.get(key)
        excluded = [r["name"] for r in shown if not r["identifiable"] and (
            r["name"].endswith(f".{symbol}") and r["name"] in DRIVE_SOURCE_NAMES if symbol else
            key == "other_max_rel_error_pct" and r["name"] not in DRIVE_SOURCE_NAMES and r["was_identified"])]
        hidden = {n: why for n, why in unobservable.items() if symbol and n.endswith(f".{symbol}")}
        value, value_ok = every[key], meaningful[key]
        out.append({"figure": key, "paper": paper, "ours": None if np.isnan(value) else float(value),
                    "beats_paper": bool(value <= paper),
                    "ours_identifiable": None if np.isnan(value_ok) else float(value_ok),
                    "beats_paper_identifiable": bool(value_ok <= paper), "not_identifiable": excluded,
                    "not_observable": hidden,
                    "shown": not (symbol and len(hidden) == 3)})
    return out


def remove_return_offsets(measurement: Measurement) -> np.ndarray:
    """Angles (n, 3) [rad] with each leg's return offset removed (paper Sec. 4.2).

    A reciprocal leg ends at the inputs of the point before it; whatever differs between
    those two readings is drift. It is spread linearly in time over the leg and taken off
    every later point. Legs that do not return are left alone."""
    angles = measurement.angles.copy()
    for leg in dict.fromkeys(measurement.leg.tolist()):
        index = np.flatnonzero(measurement.leg == leg)
        before, last = index[0] - 1, index[-1]
        if before < 0 or not np.allclose(measurement.inputs[before], measurement.inputs[last], rtol=0, atol=1e-9):
            continue
        offset = angles[last] - angles[before]
        span = max(measurement.time[last] - measurement.time[before], 1e-12)
        fraction = (measurement.time[index] - measurement.time[before]) / span
        angles[index] -= fraction[:, None] * offset
        angles[last + 1:] -= offset
    return angles


def _model_threads(settings: VerifySettings) -> int:
    """The model's threads per batch (``VerifySettings.model_threads``; None: every usable core)."""
    return usable_cores() if settings.model_threads is None else settings.model_threads


def _paper_identification(measurement: Measurement, angles: np.ndarray, space: ParameterSpace,
                          settings: VerifySettings, log, progress: bool) -> dict[str, Any]:
    """The paper's method: Sobol screening (skipped when ``settings.sources`` names the
    sources), then ``identify_swarm``: improved PSO on the selected sources, polish."""
    screening = CalibrationProblem(space=space, inputs=measurement.inputs, angles=angles,
                                   n_threads=_model_threads(settings))
    sobol, sobol_s, st = None, 0.0, None
    if settings.sources is None:
        start = time.perf_counter()
        with progress_bar(settings.sobol_n * (space.n_params + 2), "Sobol", enabled=progress, unit="run") as bar:
            sobol = sobol_indices(with_progress(screening.deviation_from_ideal, bar), [[0.0, 1.0]] * space.n_params,
                                  settings.sobol_n, seed=settings.seed, names=space.names, outputs=OUTPUTS,
                                  chunk_size=max(64, settings.sobol_n))  # chunks only so that the bar moves
        sobol_s = time.perf_counter() - start
        log(f"verify: Sobol screening, {sobol.n_evaluations} model runs in {sobol_s:.1f} s")
        selected = select_parameters(sobol, threshold=settings.sobol_threshold, always=DRIVE_SOURCE_NAMES)
        st = sobol.ST[0, [space.names.index(n) for n in selected]]
    else:
        selected = settings.sources
    log(f"verify: identifying {len(selected)} of {space.n_params} sources with the improved PSO "
        f"({settings.pso.n_particles} particles x {settings.pso.max_iterations} iterations)")
    start = time.perf_counter()
    with progress_bar(settings.pso.max_iterations, "PSO", enabled=progress, unit="iteration") as bar:
        found = identify_swarm(space, measurement.inputs, angles, selected, settings.pso, seed=settings.seed,
                               sensitivity=st, polish=settings.polish,
                               noise=settings.noise_urad * 1e-6 if settings.noise_urad else None,
                               callback=lambda _: bar.update(1), n_threads=_model_threads(settings))
    pso_s = time.perf_counter() - start
    pso, polish, ident, problem = found.pso, found.polish, found.ident, found.problem
    values, std, fitted, noise, x_best = found.values, found.std, found.fitted_angles, found.noise, found.x_unit
    return {"values": values, "std": std, "fitted": fitted, "selected": selected,
            "identifiable": set(found.identifiable), "ident": ident, "sobol": sobol, "pso": pso, "polish": polish,
            "problem": problem, "n_evaluations": int(problem.log.n_candidates + screening.log.n_candidates),
            "n_model_postures": int(problem.log.n_postures + screening.log.n_postures),
            "n_failed": int(problem.log.n_failures + screening.log.n_failures),
            "noise": noise, "noise_source": "given (--noise-urad)" if settings.noise_urad else "fit RMS",
            "timings_s": {"sobol": sobol_s, "pso": pso_s},
            "extra": {
                "sobol": None if sobol is None else {
                    "n_base": sobol.n_base, "n_evaluations": sobol.n_evaluations, "outputs": list(OUTPUTS),
                    "names": list(sobol.names), "ST": sobol.ST, "ST_conf": sobol.ST_conf, "S1": sobol.S1,
                    "note": f"N = {sobol.n_base} instead of the paper's 500 (Sobol sequences need a power of two)"},
                "pso": {"n_evaluations": pso.n_evaluations, "stagnation_iterations": list(pso.stagnation_iterations),
                        "n_subgroups": len(pso.subgroups), "history_best_f_urad": pso.history_best_f * 1e6},
                "polish": None if polish is None else {"n_evaluations": polish.n_evaluations,
                                                       "rms_urad": polish.rms * 1e6,
                                                       "used": bool(np.array_equal(x_best, polish.x))}}}


def _estimated_identification(measurement: Measurement, angles: np.ndarray, space: ParameterSpace,
                              settings: VerifySettings, log, progress: bool = False,
                              budget=None) -> dict[str, Any]:
    """MAP (cross-validated prior) or free least squares over all sources (``identify_all``)."""
    start = time.perf_counter()
    if settings.sources is not None:
        space = space.subset(settings.sources)
    made = []  # the ErrorBudget the callable makes (for the report)
    model_error = None
    if budget is not None:
        def model_error(values: np.ndarray) -> np.ndarray:
            made.append(budget(values))
            return made[-1].samples
    # the fits' dense algebra (46-column Jacobians, 231 x 231 discrepancy kernels) on one BLAS
    # thread: on 2 cores the threaded BLAS made the README's warm main job 44 s against 30 s
    # (session 21, docs/scale.md); the identified values the same to the bit, the bars to 1e-8.
    # The model's batches (a Jacobian's 46 candidates) on every usable core instead: its compiled
    # solve is per candidate, the same bits at any thread count (``model.forward``); 0.87x the
    # warm main job's wall (docs/scale.md, "Issue 26, session 32")
    with single_blas_thread(), progress_bar(None, f"{settings.method} estimate", enabled=progress,
                                            unit="fit") as bar:
        def plan(total: int) -> None:
            bar.total = total
        result = identify_all(space, measurement.inputs, angles, measurement.leg,
                              IdentificationSettings(method=settings.method, prior_scale=settings.prior_scale,
                                                     profile=settings.profile,
                                                     start=None if settings.start is None else np.array(settings.start),
                                                     n_threads=_model_threads(settings)),
                              log=log, on_fit=lambda: bar.update(1), on_plan=plan,
                              model_error=model_error)
    fit = result.estimate
    log(f"verify: {settings.method} estimate of {space.n_params} sources, {fit.n_evaluations} model runs in "
        f"{time.perf_counter() - start:.1f} s; {result.base.n_base} base parameters")
    cv = result.cross_validation
    return {"values": result.values, "std": result.std, "fitted": result.fitted_angles, "selected": space.names,
            "identifiable": set(result.identifiable), "ident": None, "sobol": None, "pso": None, "polish": None,
            "problem": result.problem, "n_evaluations": int(result.problem.log.n_candidates),
            "n_model_postures": int(result.problem.log.n_postures), "n_failed": int(result.problem.log.n_failures),
            "noise": fit.noise, "noise_source": fit.noise_source, "identification": result,
            "timings_s": {"estimate": time.perf_counter() - start},
            "extra": {"estimation": {
                "method": settings.method, "prior": "Gaussian with the moments of the paper's ranges (Eq. 9): mean "
                          "mid-range, std = scale x range / sqrt(12)",
                "prior_scale": None if math.isinf(result.prior_scale) else result.prior_scale,
                "cross_validation": None if cv is None else {
                    "scales": list(cv.scales), "held_out_rms_urad": (cv.held_out_rms * 1e6).tolist(),
                    "n_folds": cv.n_folds, "folds": "whole legs held out"},
                "stopped_at_budget": fit.stopped_at_budget,
                "noise_urad": fit.noise * 1e6, "noise_source": fit.noise_source,
                "residual_autocorrelation": fit.autocorrelation, "noise_variance_inflation": fit.inflation,
                "discrepancy": None if fit.discrepancy is None else {
                    **fit.discrepancy.as_dict(),
                    "error_bars": "sandwich covariance with the noise + model-discrepancy covariance "
                                  "(flexcal.calibration.discrepancy)"
                                  + ("" if budget is None else " + the model-error budget (flexcal.validation.runs."
                                                               "error_budget)")
                                  + ("" if fit.profile_bars is None else " + the base combinations' profile "
                                                                         "likelihood (flexcal.calibration.profile_bars)"),
                    "model_error_budget_samples": made[-1].as_dict() if made else None,
                    "profile_bars": None if fit.profile_bars is None else fit.profile_bars.as_dict()},
                "effective_parameters": fit.p_eff, "n_observations": fit.n_observations,
                "base_parameters": result.base.as_dict()}}}


def _observability(release: np.ndarray) -> dict[str, str]:
    """{drive source: why it cannot show} for the clearance and hysteresis of drives that the
    identified model keeps compressed at every posture (their gap never opens: Eq. 6-7);
    release (n, 3) [m] fx_A of D1-D3 at the identified values."""  # (n, 3) fx_A > 0: the load pulls the nut into the gap
    why = {}
    for i in range(3):
        if not np.any(release[:, i] > 0.0):
            reason = (f"not observable on this mount: drive D{i + 1} is compressed at every posture of this trajectory "
                      f"(largest release {release[:, i].max() * 1e6:.3g} um <= 0), so its clearance never opens")
            why[f"D{i + 1}.CL"] = why[f"D{i + 1}.mu"] = reason
    return why


def _base_table(identification, space: ParameterSpace, presets: np.ndarray | None) -> dict[str, Any]:
    """Each base parameter beta = C y on the estimator's unit box (``identification.chart``: the
    mount offsets as Cartesian components, ``calibration.offset_chart``): estimate, standard error
    sqrt(C Sigma C^T) (the covariance of the sources' table: a source identified alone is its own
    row, with its own error bar) and, with presets, the true beta (the presets in the same chart)
    and its z-score, ``z_rms`` over all of them. No combination holds an offset's direction, so
    none has the polar chart's undefined bar at zero offset (docs/calibration.md "Session 23")."""
    base, chart = identification.base, identification.chart
    C = base.reported_combinations(chart.names)
    estimate = C @ identification.estimate.x
    std = np.sqrt(np.einsum("kd,de,ke->k", C, identification.estimate.covariance, C))
    rows = [{"label": label, "estimate_unit": float(b), "std_unit": float(s)}
            for label, b, s in zip(base.labels, estimate, std)]
    out: dict[str, Any] = {"rows": rows, "units": "fractions of the sources' ranges (unit box, Eq. 9); a mount "
                                                  "offset (X.d, X.phi) as its Cartesian components X.dy, X.dz, "
                                                  "0.5 at zero offset (flexcal.calibration.offset_chart)",
                           "pure": list(identification.identifiable)}
    if presets is not None:
        truth = C @ chart.from_space(space.to_unit(presets[space.active_indices]))
        z = (estimate - truth) / std
        for row, t, zk in zip(rows, truth, z):
            row["true_unit"], row["z_score"] = float(t), float(zk)
        out["z_rms"] = float(np.sqrt(np.mean(z ** 2))) if z.size else None
        out["n_z_scores"] = int(z.size)
    return out


def _undetermined(space: ParameterSpace, values: np.ndarray, std: np.ndarray | None,
                  selected: tuple[str, ...]) -> dict[str, str]:
    """{"X.phi": why} of ``calibration.offset_directions.undetermined_directions`` over the
    identified sources (values, std (45,) [SI]; {} without error bars)."""
    from flexcal.calibration.offset_directions import undetermined_directions

    if std is None:
        return {}
    found = undetermined_directions([p.name for p in space.parameters], values, std)
    return {name: why for name, why in found.items() if name in selected}


def run_verify(measurement: Measurement, space: ParameterSpace, settings: VerifySettings = VerifySettings(), *,
               presets: np.ndarray | None = None, truth: TruthCurve | None = None,
               progress: bool = True, log: Callable[..., None] | None = None, budget=None) -> VerifyResult:
    """Identify and report on one measurement: ``settings.method`` "map" (default: all sources,
    cross-validated prior), "free" (all sources, no prior) or "paper" (Sobol screening +
    improved PSO); ``presets`` (45,) [SI] are the true values when the data are synthetic
    (for the error columns and z-scores); ``truth`` the curve and values the model-form
    floor is measured against (``runs.form_floor``; default: the measured curve with
    ``presets``, and "not available" without them); budget: values (45,) [SI] of the estimate
    -> its model-error budget on the measurement's inputs (``runs.error_budget.ErrorBudget``),
    for the error bars of "map" and "free" (None: the residual-fitted discrepancy alone)."""
    from flexcal.model.forward import CLASS_NAMES, forward, ideal_angles

    if log is None:  # progress bars on stderr, the stage lines on stdout
        log = print if progress else (lambda *a, **k: None)
    t0 = time.perf_counter()
    angles = remove_return_offsets(measurement) if settings.remove_offset else measurement.angles
    if settings.method == "paper":
        core = _paper_identification(measurement, angles, space, settings, log, progress)
    else:
        core = _estimated_identification(measurement, angles, space, settings, log, progress, budget)
    values, fitted = core["values"], core["fitted"]
    residual = fitted - angles
    fit_rms = float(np.sqrt(np.mean(residual ** 2)))
    model = forward(values, measurement.inputs, space=space)
    classes = tuple(CLASS_NAMES[int(c)] for c in model.point_class[0])
    unobservable = _observability(model.release[0])
    undetermined = _undetermined(space, values, core["std"], core["selected"])
    rows = _parameter_rows(space, values, presets, core["selected"], core["identifiable"], std=core["std"],
                           unobservable=unobservable, undetermined=undetermined)
    per_point = np.linalg.norm(residual, axis=1)
    noise_floor = settings.noise_urad * 1e-6 if settings.noise_urad else None
    report: dict[str, Any] = {
        "method": settings.method,
        "parameters": rows,
        "selected": list(core["selected"]),
        "identifiable": sorted(core["identifiable"], key=space.all_names.index),
        "fit_rms_urad": fit_rms * 1e6,
        "fit_rms_per_angle_urad": (np.sqrt(np.mean(residual ** 2, axis=0)) * 1e6).tolist(),
        "fit_max_urad": float(per_point.max() * 1e6),
        "fitness_eq13_urad": float(per_point.mean() * 1e6),
        "fit_rms_over_noise_floor": None if noise_floor is None else fit_rms / noise_floor,
        "noise_urad": core["noise"] * 1e6,
        "noise_source": core["noise_source"],
        "n_points": measurement.n_points,
        "n_evaluations": core["n_evaluations"],
        "n_model_postures": core["n_model_postures"],
        "n_failed_candidates": core["n_failed"],
        "wall_s": time.perf_counter() - t0,
        "timings_s": core["timings_s"],
        "offset_removed": settings.remove_offset,
        "point_class": list(classes),
        "not_observable": unobservable,
        **core["extra"],
    }
    if truth is None and presets is not None:
        truth = TruthCurve(angles=measurement.angles, presets=presets,
                           source="measured curve, its noise and sensor offset left in (no noise-free curve given)")
    report["model_form_floor"] = not_available() if truth is None else model_form_floor(
        truth, measurement.inputs, space, fit_residual=residual)
    ident = core["ident"]
    if ident is not None:
        report["identifiability"] = {"rank": ident.rank, "n_parameters": len(ident.names),
                                     "condition_number": ident.condition_number,
                                     "condition_number_subset": ident.condition_number_subset,
                                     "singular_values": ident.singular_values,
                                     "groups": [list(g) for g in ident.groups],
                                     "meaningful": list(ident.meaningful_names)}
    else:
        base = core["identification"].base
        report["identifiability"] = {"rank": base.n_base, "n_parameters": len(core["selected"]),
                                     "base_parameters": list(base.labels), "groups": [],
                                     "meaningful": list(base.base)}
    if core.get("identification") is not None:
        identified = core["identification"]
        report["base_parameters"] = _base_table(identified, identified.problem.space, presets)
    if presets is not None:
        z = [r["z_score"] for r in rows if r["identifiable"] and r.get("z_score") is not None]
        report["z_rms_identifiable"] = float(np.sqrt(np.mean(np.square(z)))) if z else None
        report["n_z_scores"] = len(z)
        report["paper_comparison"] = _paper_comparison(rows, report["fit_max_urad"], unobservable)
    return VerifyResult(report=report, values=values, std=core["std"], sobol=core["sobol"], pso=core["pso"],
                        polish=core["polish"], identifiability=ident, identification=core.get("identification"),
                        problem=core["problem"], fitted_angles=fitted,
                        ideal_angles=ideal_angles(measurement.inputs, space), point_class=classes)
