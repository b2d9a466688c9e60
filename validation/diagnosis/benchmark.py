"""The blind benchmark of the gap diagnosis (issue #7, docs/diagnosis.md).

For every effect of the library, ``none`` and the out-of-library effects, at several
magnitudes (multiples of the sensor noise) and seeds: make prototype data with that effect
injected, keep the answer apart (``answer`` of ``BenchmarkCase``, written to
``answers.json`` by the command; the measurement handed to the diagnosis carries no
sidecar), diagnose, and score: confusion matrix, detection rate against magnitude, false
alarms on ``none``, predicted against achieved shrink on held-out legs.

Benchmark data: the table1 scenario (seeded draws of the other 42 sources vary with the
case seed), the standard trajectory (or a given one, e.g. ``flexcal design``'s) repeated
``cycles`` times (legs numbered uniquely per cycle, so leaving one leg out still leaves that
actuator's motion in another cycle), noise ``noise_urad`` per channel. Provider: analytic
segments (fast; CI grid) or FEM (slow grid).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from ..measurements import Measurement

__all__ = ["BenchmarkCase", "benchmark_measurement", "run_case", "summarize", "GRIDS", "repeated_trajectory",
           "trajectory_digest"]

# name -> (magnitudes [x noise], seeds, extra none seeds)
GRIDS = {
    "tiny": ((10.0,), (0,), 1),
    "small": ((3.0, 10.0), (0,), 4),
    "full": ((1.0, 3.0, 10.0), (0, 1, 2), 10),
}
GOAL_DETECTION = 0.90  # correct top effect (or group) at magnitudes >= 3 noise floors
GOAL_FALSE_ALARM = 0.05  # on none
GOAL_CLOSURE = 0.70  # share of the held-out gap above the noise floor removed


@dataclass(frozen=True, kw_only=True, eq=False)
class BenchmarkCase:
    """measurement: what the diagnosis sees (no metadata); answer: what was injected."""

    measurement: Measurement
    answer: dict[str, Any]


def repeated_trajectory(cycles: int, trajectory: tuple[np.ndarray, np.ndarray] | None = None, mechanism=None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """A trajectory ``cycles`` times: (inputs (n, 3) [m], leg (n,)).

    trajectory: (inputs (k, 3) [m], leg (k,)) of one cycle (default: the standard
    trajectory of ``mechanism``, the reference mount's by default, legs 0, 1..3). The
    first cycle is the whole trajectory; each later one repeats its points of legs >= 1
    (the start posture, leg 0, is not measured again) with the legs numbered on after the
    previous cycle's (leg + c max(leg)): the standard trajectory twice has legs 0, 1..6."""
    from flexcal.model.trajectory import standard_trajectory

    if cycles < 1:
        raise ValueError(f"cycles={cycles} must be >= 1")
    if trajectory is None:
        standard = standard_trajectory(mechanism)
        trajectory = (standard.inputs, standard.leg)
    inputs, leg = np.asarray(trajectory[0], float), np.asarray(trajectory[1], int)
    if inputs.ndim != 2 or inputs.shape[1] != 3 or leg.shape != inputs.shape[:1]:
        raise ValueError(f"trajectory inputs {inputs.shape} and leg {leg.shape} must be (n, 3) and (n,)")
    body = leg > 0
    n_legs = int(leg.max(initial=0))
    return (np.concatenate([inputs] + [inputs[body]] * (cycles - 1)),
            np.concatenate([leg] + [leg[body] + n_legs * c for c in range(1, cycles)]))


def trajectory_digest(inputs: np.ndarray, leg: np.ndarray) -> str:
    """A short content hash of a trajectory (inputs (n, 3) [m] to 1 nm, leg (n,)): the
    benchmark's case ids and report name a trajectory file by it, not by its path."""
    import hashlib

    nanometres = np.round(np.asarray(inputs, float) * 1e9).astype(np.int64)
    text = nanometres.tobytes() + np.asarray(leg, np.int64).tobytes()
    return hashlib.sha256(text).hexdigest()[:16]


def benchmark_measurement(effect_id: str, magnitude: float, seed: int, provider, *, cycles: int = 2,
                          noise_urad: float = 0.5, scenario_seed: int | None = None,
                          trajectory: tuple[np.ndarray, np.ndarray] | None = None, mechanism=None) -> BenchmarkCase:
    """One blind case. effect_id: a library id, an out-of-library id or "none"; magnitude:
    the injected signature RMS in multiples of ``noise_urad`` [-] on the standard trajectory
    (``make_injector``; the answer also holds the achieved one on this file:
    ``achieved_magnitude_noise``); scenario_seed: the table1 draws and the sensor noise
    (default 1000 + seed, a new as-built mount per case; a fixed one keeps the FEM cache
    warm but repeats the noise); trajectory: (inputs (k, 3) [m], leg (k,)) of one cycle
    (default the standard trajectory), measured ``cycles`` times (``repeated_trajectory``);
    mechanism: the mount the table1 errors are drawn on (``MechanismParams``, ``--mount``;
    default the reference mount). The effects' nominal magnitudes are scaled on that mount's
    standard setting (``effects.magnitude``); the answer's achieved magnitude is measured on
    this file."""
    from ..effects.library import NONE, make_injector
    from ..prototype.scenario import load_scenario
    from ..prototype.truth import make_truth

    scenario = load_scenario("table1", seed=1000 + seed if scenario_seed is None else scenario_seed,
                             noise_urad=noise_urad, mount=mechanism)
    inputs, leg = repeated_trajectory(cycles, trajectory, mechanism)
    scenario = dataclasses.replace(scenario, inputs=inputs, leg=leg)
    effects = ()
    if effect_id != NONE:
        rng = np.random.default_rng([seed, 7])
        effects = (make_injector(effect_id, magnitude * noise_urad, rng, mechanism=mechanism),)
    truth = make_truth(scenario, provider, effects=effects)
    blind = dataclasses.replace(truth.measurement, metadata={})
    answer = {"effect": effect_id, "magnitude_noise": float(magnitude), "magnitude_urad": float(magnitude * noise_urad),
              "seed": int(seed), "scenario_seed": int(scenario.seed), "noise_urad": float(noise_urad),
              "cycles": int(cycles), "trajectory": "standard" if trajectory is None else trajectory_digest(*trajectory),
              "injected": truth.measurement.metadata.get("injected_effects", [])}
    if effects:
        # what was really injected into this file: the noise-free angles with the effect minus
        # the same mount without it (the nominal magnitude is a linearized estimate on one
        # standard cycle; path-dependent effects such as a lost step carry into the next)
        clean = make_truth(scenario, provider).run.angles
        achieved = float(np.sqrt(np.mean((truth.run.angles - clean) ** 2))) * 1e6
        answer.update(achieved_rms_urad=achieved, achieved_magnitude_noise=achieved / noise_urad)
    return BenchmarkCase(measurement=blind, answer=answer)


def run_case(case: BenchmarkCase, diagnose: Callable[[Measurement], Any]) -> dict[str, Any]:
    """Diagnose a case (the callable gets only the measurement) and score it against its answer."""
    from ..effects.library import EFFECT_IDS, NONE

    report = diagnose(case.measurement).report
    truth = case.answer["effect"]
    group = report["top_group"] or [report["top_effect"]]
    in_library = truth in EFFECT_IDS
    row = {**{k: case.answer[k] for k in ("effect", "magnitude_noise", "seed")},
           "achieved_magnitude_noise": case.answer.get("achieved_magnitude_noise"),
           "predicted": report["top_effect"], "group": group, "confidence": report["confidence"],
           "noise_floor_urad": report["noise_floor_urad"], "closure": report["how_far"]["closure"]}
    noise = report.get("correlated_noise") or {}
    row["detected_by"], row["noise_z"] = report.get("detected_by"), noise.get("z")
    separation = report.get("separation") or {}
    row["separation"] = {k: separation.get(k) for k in ("separated", "closest", "closure_on_closest", "runner_up")}
    row["top3"] = [{k: r[k] for k in ("effect", "closure", "gain_noise_variances", "delta_bic", "significant")}
                   for r in report["ranking"][:3]]
    if in_library:
        row["correct"] = truth in group
        row["absorbed"] = report["collinearity"]["absorbed_by_baseline"].get(truth)
        # the diagnosis named it undetectable (its signature is a baseline calibration error)
        row["reported_undetectable"] = report["top_effect"] == NONE and truth in report.get("undetectable", [])
        entry = next((r for r in report["ranking"] if r["effect"] == truth), None)
        # achieved shrink of the TRUE effect's term on held-out legs (predicted: the winner's)
        row["true_term_closure"] = None if entry is None else entry["closure"]
        winner = next((r for r in report["ranking"] if r["effect"] == report["top_effect"]), None)
        row["predicted_closure"] = None if winner is None else winner["closure"]
    elif truth == NONE:
        row["correct"] = report["top_effect"] == NONE
    else:  # out of library: no confident claim of a library effect
        row["correct"] = report["confidence"] != "high"
        # "where": a concentrated stratum, or structure along the sequence (runs, period)
        structure = report["where"].get("structure", [])
        row["where_named"] = len(report["where"]["concentrated"]) > 0 or any(
            s["runs_z"] < -3 or s["p_value"] < 0.01 for s in structure)
    return row


def summarize(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Confusion matrix (truth -> predicted counts), detection rate per magnitude, false
    alarms on none, closure statistics and the goals met or missed."""
    from ..effects.library import EFFECT_IDS, NONE

    confusion: dict[str, dict[str, int]] = {}
    for r in rows:
        confusion.setdefault(r["effect"], {}).setdefault(r["predicted"], 0)
        confusion[r["effect"]][r["predicted"]] += 1
    library = [r for r in rows if r["effect"] in EFFECT_IDS]
    detection = {}
    for m in sorted({r["magnitude_noise"] for r in library}):
        at = [r for r in library if r["magnitude_noise"] == m]
        detection[f"{m:g}"] = float(np.mean([r["correct"] for r in at]))
    strong = [r for r in library if r["magnitude_noise"] >= 3.0]
    # by the magnitude really injected into the file (None for rows made before it was recorded)
    measured = [r for r in library if r.get("achieved_magnitude_noise") is not None]
    strong_achieved = [r for r in measured if r["achieved_magnitude_noise"] >= 3.0]
    nones = [r for r in rows if r["effect"] == NONE]
    outside = [r for r in rows if r["effect"] not in EFFECT_IDS and r["effect"] != NONE]
    closures = [r["true_term_closure"] for r in strong if r.get("true_term_closure") is not None]
    detect_strong = float(np.mean([r["correct"] for r in strong])) if strong else float("nan")
    visible = [r for r in strong if not r.get("reported_undetectable")]
    detect_visible = float(np.mean([r["correct"] for r in visible])) if visible else float("nan")
    false_alarm = float(np.mean([not r["correct"] for r in nones])) if nones else float("nan")
    closure_median = float(np.median(closures)) if closures else float("nan")
    closure_share = float(np.mean(np.array(closures) >= GOAL_CLOSURE)) if closures else float("nan")
    return {
        "confusion": confusion,
        "detection_by_magnitude": detection,
        "detection_at_3x_or_more": detect_strong,
        "detection_at_achieved_3x_or_more": (float(np.mean([r["correct"] for r in strong_achieved]))
                                             if strong_achieved else None),
        "n_at_achieved_3x_or_more": len(strong_achieved),
        "detection_at_3x_excluding_reported_undetectable": detect_visible,
        "n_reported_undetectable_at_3x": len(strong) - len(visible),
        "false_alarm_rate_none": false_alarm,
        "out_of_library_no_confident_claim": float(np.mean([r["correct"] for r in outside])) if outside else None,
        "out_of_library_where_named": float(np.mean([r["where_named"] for r in outside])) if outside else None,
        "closure_true_term_median": closure_median,
        "closure_share_at_least_goal": closure_share,
        "predicted_vs_achieved": [{"effect": r["effect"], "magnitude_noise": r["magnitude_noise"],
                                   "predicted_closure": r.get("predicted_closure"),
                                   "achieved_closure": r.get("true_term_closure")} for r in strong],
        "goals": {
            "detection_at_3x": {"goal": GOAL_DETECTION, "measured": detect_strong,
                                "met": bool(detect_strong >= GOAL_DETECTION),
                                "margin": detect_strong - GOAL_DETECTION},
            "false_alarms_none": {"goal": GOAL_FALSE_ALARM, "measured": false_alarm,
                                  "met": bool(false_alarm <= GOAL_FALSE_ALARM),
                                  "margin": GOAL_FALSE_ALARM - false_alarm},
            "closure_median": {"goal": GOAL_CLOSURE, "measured": closure_median,
                               "met": bool(closure_median >= GOAL_CLOSURE), "margin": closure_median - GOAL_CLOSURE},
        },
    }
