"""The sim-to-real gap diagnosis of one measurement (issue #7, docs/diagnosis.md).

``run_diagnosis(measurement)``: calibrate the baseline (``diagnosis.baseline``, swappable),
say where the residual lies (``diagnosis.where``), rank the effect library's terms on
held-out legs with information criteria and collinearity groups (``diagnosis.which``), add
the winner and repeat on what is left. The measurement's JSON sidecar is never read here
(a blind benchmark keeps its answer in a separate file anyway).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from .baseline import BaselineFit, calibrate_baseline
from .correlated import correlated_noise
from .null import NullModel
from .separation import RUNNER_UP_RATIO, runner_up, separation
from .where import concentration, noise_floor, strata, structure_tests
from .which import (CriterionSettings, Candidate, cross_validate, fit_terms, leg_folds, make_problem, principal_cosines, score_candidates)
from ..measurements import Measurement

__all__ = ["Diagnosis", "run_diagnosis", "library_terms", "check_measurement", "share_not_repeated", "MIN_POINTS",
           "MAX_STAGES"]

MIN_POINTS = 20  # fewer points cannot support a 45-source baseline plus a held-out leg
ABSORBED_LIMIT = 0.99  # a term whose signature the baseline mimics to this share is undetectable on the trajectory
MAX_STAGES = 3  # effects added one after another at most (a fourth has never been significant in the benchmark)
ANGLES = ("theta_x", "theta_y", "theta_z")


@dataclass(frozen=True, kw_only=True, eq=False)
class Diagnosis:
    """report: the JSON-ready report; residual (n, 3) [rad] measured - baseline; heldout_before /
    heldout_after (n, 3) [rad] held-out residuals without / with the accepted effects;
    baseline: the ``BaselineFit``; folds: held-out masks; stages: accepted effect ids."""

    report: dict[str, Any]
    residual: np.ndarray
    heldout_before: np.ndarray
    heldout_after: np.ndarray
    baseline: BaselineFit
    folds: tuple
    stages: tuple[str, ...]


def library_terms(extras: dict) -> tuple[list, list[str]]:
    """(terms usable with these extra columns, ids skipped for a missing column)."""
    from ..effects.library import EFFECT_IDS, model_term

    terms, skipped = [], []
    for effect_id in EFFECT_IDS:
        term = model_term(effect_id)
        if all(column in extras for column in term.requires):
            terms.append(term)
        else:
            skipped.append(effect_id)
    return terms, skipped


def check_measurement(measurement: Measurement) -> None:
    """Raise ValueError if the diagnosis cannot use ``measurement`` (too few points or legs)."""
    if measurement.n_points < MIN_POINTS:
        raise ValueError(f"the measurement has {measurement.n_points} points; the diagnosis needs at least "
                         f"{MIN_POINTS} (a calibration trajectory, e.g. the standard one of 77 points)")
    if len(np.unique(measurement.leg[measurement.leg > 0])) < 2:
        raise ValueError("the measurement has fewer than two legs (column 'leg' >= 1); held-out scoring leaves "
                         "whole legs out, so number the legs of the trajectory")


def share_not_repeated(inputs: np.ndarray, folds, atol: float = 1e-9) -> float:
    """Share [-] of the held-out points whose posture (inputs (n, 3) [m], equal within
    ``atol`` [m]) is measured at no point outside their fold. 0 when every held-out posture
    is repeated in the training legs (the standard trajectory measured twice); near 1 for
    one pass of a designed trajectory, where each leg visits its own postures and the held-out
    scores extrapolate the baseline (docs/diagnosis.md, "Designed trajectory")."""
    key = np.round(np.asarray(inputs, float) / atol).astype(np.int64)
    held, alone = 0, 0
    for fold in folds:
        training = {tuple(row) for row in key[~fold]}
        held += int(np.count_nonzero(fold))
        alone += sum(tuple(row) not in training for row in key[fold])
    return alone / held if held else 0.0


def _effective_dof(J: np.ndarray, prior_sd: np.ndarray) -> float:
    """Trace of the ridge hat matrix of the whitened baseline Jacobian J (m, p) [-]."""
    s = np.linalg.svd(J, compute_uv=False)
    if np.allclose(prior_sd, prior_sd[0]):
        return float(np.sum(s**2 / (s**2 + 1.0 / prior_sd[0] ** 2)))
    A = J.T @ J
    return float(np.trace(np.linalg.solve(A + np.diag(1.0 / prior_sd**2), A)))


def _collinearity(problem, ids: Sequence[str]) -> dict[str, Any]:
    """Baseline-residualized signature columns: the share of each term the baseline can mimic
    and the largest principal-angle cosine between every pair of terms."""
    w = 1.0 / problem.sigma
    J = (problem.baseline * w[None, :, None]).reshape(-1, problem.baseline.shape[-1])
    augmented = np.vstack([J, np.diag(1.0 / problem.prior_sd)])
    residualized, absorbed = {}, {}
    for i in ids:
        G = (problem.columns[i] * w[None, :, None]).reshape(J.shape[0], -1)
        rhs = np.vstack([G, np.zeros((J.shape[1], G.shape[1]))])
        R = G - J @ np.linalg.lstsq(augmented, rhs, rcond=None)[0]
        residualized[i] = R
        norm = float(np.sum(G**2))
        absorbed[i] = float(1.0 - np.sum(R**2) / norm) if norm > 0 else 1.0
    cosines = {a: {b: float(principal_cosines(residualized[a], residualized[b])[:1].max(initial=0.0))
                   for b in ids if b != a} for a in ids}
    return {"absorbed_by_baseline": absorbed, "max_principal_cosine": cosines}


def _group(winner: Candidate, ranked: list[Candidate], chi2_before: float, ratio: float) -> list[str]:
    """The winner and every term that explains >= ratio of its in-sample gain and of its
    held-out closure: the data cannot tell them apart."""
    gain = chi2_before - winner.chi2
    return [c.id for c in ranked if c.id == winner.id or
            (chi2_before - c.chi2 >= ratio * gain and c.closure >= ratio * winner.closure)]


def _row(c: Candidate, group: list[str] | None = None) -> dict[str, Any]:
    return {"effect": c.id, "score": c.closure, "heldout_rms_before_urad": np.sqrt(c.heldout_ms_before) * 1e6,
            "heldout_rms_after_urad": np.sqrt(c.heldout_ms_after) * 1e6, "closure": c.closure,
            "gain_noise_variances": c.gain_noise, "delta_aicc": c.delta_aicc, "delta_bic": c.delta_bic,
            "n_params": c.n_params, "significant": c.significant, **({"group": group} if group else {})}


def run_diagnosis(measurement: Measurement, *, baseline: Callable[..., BaselineFit] = calibrate_baseline,
                  terms: Sequence | None = None, settings: CriterionSettings = CriterionSettings(),
                  rng=None, progress: bool = False, null: NullModel | None = None) -> Diagnosis:
    """Diagnose the gap of ``measurement`` (module docstring).

    baseline(measurement, rng=, progress=) -> BaselineFit; terms: ``ModelTerm`` candidates
    (default: the effect library's, minus those whose extra column is missing); rng: seed of
    the baseline's optimizer; null: the terms' gains on `none` files of the same trajectory
    (``diagnosis.null``): each term must also gain ``NULL_FACTOR`` x its own (None: the
    fixed threshold alone, as calibrated on the standard trajectory)."""
    from flexcal.model.trajectory import travel_directions

    from ..blas_threads import single_blas_thread
    from ..effects.terms import TermData

    check_measurement(measurement)
    fit = baseline(measurement, rng=rng, progress=progress)
    residual = measurement.angles - fit.model_angles
    direction = travel_directions(measurement.inputs)
    floor = noise_floor(residual, measurement.leg, measurement.angles, measurement.inputs, direction)
    sigma = floor["sigma"]
    skipped: list[str] = []
    if terms is None:
        terms, skipped = library_terms(measurement.extras)
    data = TermData(inputs=measurement.inputs, time=measurement.time, leg=measurement.leg, direction=direction,
                    model_angles=fit.model_angles, axial_loads=fit.axial_loads, input_jacobian=fit.input_jacobian,
                    extras=dict(measurement.extras))
    with single_blas_thread():
        problem = make_problem(residual, sigma, fit.jacobian, fit.prior_sd, data, terms)
        folds, unit = leg_folds(measurement.leg, measurement.inputs, direction)
        Jw = (fit.jacobian / sigma[None, :, None]).reshape(-1, fit.jacobian.shape[-1])
        k_baseline = _effective_dof(Jw, fit.prior_sd)
        ids = [t.id for t in terms]
        min_gain = {} if null is None else {i: null.min_gain(i, settings.min_gain_noise) for i in ids}
        stages, accepted, first_ranking, groups = [], [], None, []
        candidates = list(ids)
        for _ in range(MAX_STAGES):
            if not candidates:
                break
            ranked, ms0 = score_candidates(problem, accepted, candidates, folds, settings, k_baseline,
                                           min_gain)
            chi2_before = fit_terms(problem, accepted).chi2
            best = next((c for c in ranked if c.significant), None)
            group = _group(best, ranked, chi2_before, settings.group_ratio) if best else []
            rows = [_row(c, group if c.id == (best.id if best else None) else None) for c in ranked]
            if first_ranking is None:
                first_ranking = rows
            stages.append({"accepted_before": list(accepted), "ranking": rows,
                           "winner": best.id if best else "none", "group": group,
                           "heldout_rms_before_urad": np.sqrt(ms0) * 1e6})
            if best is None:
                break
            groups.append(group)
            accepted.append(best.id)
            candidates = [c for c in candidates if c not in group]
        winner_closure = next((r["closure"] for r in first_ranking if r["effect"] == accepted[0]), 0.0) \
            if accepted else 0.0
        # the look-alike test only where it can change the answer (a winner closing enough for `high`)
        collinear = _collinearity(problem, ids)
        separated = (separation(problem, accepted[0], groups[0], folds, settings.confident_closure,
                                collinear["max_principal_cosine"][accepted[0]])
                     if accepted and winner_closure >= settings.confident_closure else None)
        if separated is not None:
            second = runner_up(first_ranking, accepted[0], groups[0])
            close = second is not None and second["ratio"] >= RUNNER_UP_RATIO
            separated = {**separated, "runner_up": second, "separated_from_lookalikes": separated["separated"],
                         "separated": bool(separated["separated"] and not close)}
        cv_before = cross_validate(problem, [], folds)
        cv_after = cross_validate(problem, accepted, folds)
        final = fit_terms(problem, accepted)
        noise_test = _noise_test(problem, residual - final.explained, measurement.inputs, direction, measurement.time)
    report = _report(measurement, fit, residual, floor, unit, folds, first_ranking, stages, groups, accepted,
                     collinear, cv_before, cv_after, final, skipped, settings, k_baseline)
    report["separation"] = separated
    report["null"] = None if null is None else {**null.as_dict(), "min_gain": min_gain}
    if separated is not None and not separated["separated"]:
        report["confidence"] = "low"  # a look-alike outside the library would have been named the same
    report["correlated_noise"] = noise_test
    report["detected_by"] = "heldout" if accepted else "none"
    if noise_test["correlated"] and noise_test["effect"] is not None:
        report.update(_noise_answer(noise_test["effect"], report["top_group"] if accepted else []))
    return Diagnosis(report=report, residual=residual, heldout_before=cv_before, heldout_after=cv_after,
                     baseline=fit, folds=tuple(folds), stages=tuple(accepted))


def _noise_answer(noise_effect: str, group: list[str]) -> dict[str, Any]:
    """The answer when what is left after the accepted effects is still correlated in time and
    not repeated (``correlated.correlated_noise``): the library's noise effect, never `high`
    (any random cause outside the library leaves the same: docs/diagnosis.md). With no
    accepted effect (empty ``group``) it is the answer; with one, the noise joins the winner's
    group: the slow part of a correlated noise is what a term smooth in time (drift, a step)
    takes on held-out legs, so the data cannot tell whether the winner is there as well."""
    if not group:
        return {"top_effect": noise_effect, "top_group": [noise_effect], "confidence": "low",
                "detected_by": "correlated noise"}
    return {"top_group": list(dict.fromkeys([*group, noise_effect])), "confidence": "low",
            "detected_by": "heldout and correlated noise"}


def _noise_test(problem, left, inputs, direction, time) -> dict[str, Any]:
    """``correlated.correlated_noise`` of what is left (n, 3) [rad] after the baseline and the
    accepted effects, time (n,) [s]; "effect": the library's noise effect among the candidates (None if not)."""
    from ..effects.chain import NOISE_EFFECTS

    noise = [i for i in problem.terms if i in NOISE_EFFECTS]
    return {**correlated_noise(left, problem.sigma, inputs, direction, time), "effect": noise[0] if noise else None}


def _report(measurement, fit, residual, floor, unit, folds, ranking, stages, groups, accepted, collinear,
            cv_before, cv_after, final, skipped, settings, k_baseline) -> dict[str, Any]:
    sigma = floor["sigma"]
    overall = np.sqrt(np.mean(residual**2, axis=0)) * 1e6
    rows = strata(residual, leg=measurement.leg, direction=_directions(measurement), point_class=fit.point_class,
                  time=measurement.time, inputs=measurement.inputs, extras=measurement.extras)
    top = accepted[0] if accepted else "none"
    confident = bool(accepted) and next(r for r in ranking if r["effect"] == top)["closure"] >= settings.confident_closure
    before = np.sqrt(np.nanmean(cv_before**2, axis=0))
    after = np.sqrt(np.nanmean(cv_after**2, axis=0))
    gap = np.sum(np.maximum(before**2 - sigma**2, 0.0))
    return {
        "top_effect": top,
        "top_group": groups[0] if groups else [],
        "confidence": "high" if confident else ("low" if accepted else "none"),
        "accepted_effects": list(accepted),
        "ranking": ranking,
        "stages": stages,
        "noise_floor_urad": float(np.sqrt(np.mean(sigma**2)) * 1e6),
        "noise_floor_per_angle_urad": sigma * 1e6,
        "noise_floor": {"method": floor["method"],
                        "repeats_urad": None if floor["sigma_repeats"] is None else floor["sigma_repeats"] * 1e6,
                        "n_repeat_pairs": floor["n_repeat_pairs"]},
        "where": {"overall_rms_urad": overall, "max_abs_urad": np.abs(residual).max(axis=0) * 1e6,
                  "concentrated": concentration(rows, overall, sigma * 1e6), "strata": rows,
                  "structure": structure_tests(residual),
                  "residual_after_rms_urad": np.sqrt(np.mean((residual - final.explained) ** 2, axis=0)) * 1e6},
        "how_far": {"heldout_rms_before_urad": before * 1e6, "heldout_rms_after_urad": after * 1e6,
                    "closure": float((np.sum(before**2) - np.sum(after**2)) / gap) if gap > 0 else 0.0,
                    "effects": list(accepted),
                    "fitted_parameters": {k: {"names": list(_term_names(k)), "values": v}
                                          for k, v in final.params.items()}},
        "collinearity": collinear,
        "undetectable": sorted(k for k, v in collinear["absorbed_by_baseline"].items() if v >= ABSORBED_LIMIT),
        "baseline": {"description": fit.description, "n_sources": len(fit.names),
                     "effective_parameters": k_baseline, "wall_s": fit.wall_s,
                     "in_sample_rms_urad": overall},
        "heldout": {"unit": unit, "n_folds": len(folds),
                    "share_not_repeated": share_not_repeated(measurement.inputs, folds)},
        "skipped_terms": skipped,
        "criteria": {"min_delta_bic": settings.min_delta_bic, "min_closure": settings.min_closure,
                     "min_gain_noise": settings.min_gain_noise, "group_ratio": settings.group_ratio,
                     "confident_closure": settings.confident_closure},
        "n_points": int(measurement.n_points),
    }


def _directions(measurement: Measurement) -> np.ndarray:
    from flexcal.model.trajectory import travel_directions

    return travel_directions(measurement.inputs)


def _term_names(effect_id: str) -> tuple[str, ...]:
    from ..effects.library import LIBRARY

    entry = LIBRARY.get(effect_id)
    return entry.term.parameter_names if entry is not None and entry.term is not None else ()
