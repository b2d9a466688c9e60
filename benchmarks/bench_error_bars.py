"""Honest error bars and designed vs standard trajectories, pooled over seeds (issue #28).

    .venv/bin/python benchmarks/bench_error_bars.py --out runs/bench-bars [--scenarios table1,paper]
        [--seeds 1,2,3] [--designs table1=runs/design/trajectory.csv,paper=runs/design-paper/trajectory.csv]
        [--provider fem] [--noise-urad 0.5] [--walk-seed 101]

For every scenario x seed x trajectory (the standard one and, with --designs, the designed one)
it runs what ``flexcal truth`` + ``flexcal verify`` (map) run: the virtual prototype's curve
with the sensor noise, then ``identify_all``; and scores, against the scenario's true values:

- z-scores (estimate - truth) / std of the sources identified alone and of the base parameters,
  with the error bars of this code (``Estimate.covariance``: model discrepancy, sandwich) and
  with the Gauss-Newton ones it replaced (``Estimate.gauss_newton_covariance``, the AR(1)-inflated
  noise; base parameters over ``BaseParameters.combinations`` as before);
- the width ratio new / old of the standard errors of the sources identified alone;
- the absolute errors of the drive sources identified alone;
- the RMS [urad] with which the identified model predicts a held-out random multi-actuator walk
  (``bench_form_error.random_walk``: 60 points, stroke 0.8, seed [walk-seed, seed]) of the same
  prototype, noise-free.

Each case is appended to OUT/cases.jsonl as it finishes (a rerun skips the cases done); the
pooled tables are printed at the end (RMS over every z-score of a scenario x trajectory).
Not a test (minutes per case on the FEM prototype): the figures go into docs/calibration.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_form_error import random_walk  # noqa: E402

DRIVES = ("D1.x0", "D2.x0", "D3.x0", "D1.CL", "D2.CL", "D3.CL", "D1.mu", "D2.mu", "D3.mu")


def _z(x, truth, covariance, C):
    std = np.sqrt(np.einsum("kd,de,ke->k", C, covariance, C))
    return (C @ (x - truth)) / std


def run_case(scenario_name: str, seed: int, trajectory: str | None, provider, noise_urad: float,
             walk_seed: int, model: tuple[str, str, bool] = ("second-order", "fem", True),
             arrays: Path | None = None, budget_draws: int | None = None, profile: bool = False) -> dict:
    from flexcal.calibration.pipeline import identify_all
    from flexcal.model.trajectory import standard_trajectory
    from flexcal.validation.measurements import read_trajectory
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import make_truth
    from flexcal.validation.runs.model_correction import model_space

    scenario = load_scenario(scenario_name, seed=seed, noise_urad=noise_urad)
    if trajectory:
        inputs, leg = read_trajectory(trajectory)
        scenario = dataclasses.replace(scenario, inputs=inputs, leg=leg)
    measurement = make_truth(scenario, provider).measurement
    kind, stiffness, second_order = model
    space = model_space(stiffness, second_order, progress=False, mechanism=scenario.space.mechanism, model=kind)
    budget = None
    if budget_draws is not None:  # the model-error budget flexcal verify computes (validation.runs.error_budget)
        from flexcal.validation.runs.error_budget import budget_at_estimate

        made = []
        budget = budget_at_estimate(space, measurement.inputs, provider, n_draws=budget_draws, record=made)
    from flexcal.calibration.pipeline import IdentificationSettings

    found = identify_all(space, measurement.inputs, measurement.angles, measurement.leg, model_error=budget,
                         settings=IdentificationSettings(profile=profile))
    budget = made[-1].samples if budget is not None else None
    # the estimate, its bars and base parameters are in the estimator's chart (the mount offsets
    # as Cartesian components, calibration.offset_chart): the truth is mapped alike
    fit, base, names = found.estimate, found.base, list(found.chart.names)
    truth = found.chart.from_space(space.to_unit(scenario.values[space.active_indices]))
    pure = list(base.pure())
    E = np.eye(len(names))[[names.index(n) for n in pure]]
    old = fit.gauss_newton_covariance if fit.gauss_newton_covariance is not None else fit.covariance
    ranges = np.array(space.upper - space.lower, float)
    for i, j in found.chart.pairs:  # an offset component's unit spans [-d_max, d_max]
        ranges[i] = ranges[j] = 2.0 * ranges[i]
    errors = {n: float(abs(fit.x[names.index(n)] - truth[names.index(n)]) * ranges[names.index(n)]) for n in pure}
    walk_inputs = random_walk(standard_trajectory(scenario.space.mechanism).amplitudes, 60, 0.8, [walk_seed, seed])
    walk = dataclasses.replace(scenario, inputs=walk_inputs, leg=np.ones(60, int), noise=np.zeros(3))
    walk_angles = make_truth(walk, provider).measurement.angles
    from flexcal.calibration.problem import CalibrationProblem

    predicted = CalibrationProblem(space=space, inputs=walk_inputs, angles=walk_angles).residuals(found.x_unit[None])[0]
    if arrays is not None:  # what the error bars are computed from, to recompute them on the same fit
        from flexcal.model.trajectory import WORKSPACE

        arrays.mkdir(parents=True, exist_ok=True)
        np.savez(arrays / f"{scenario_name}-{seed}-{Path(trajectory).stem if trajectory else 'standard'}.npz",
                 residual=fit.residual, jacobian=fit.jacobian, x=fit.x, truth=truth, prior_mean=fit.prior.mean,
                 prior_std=fit.prior.std, prior_precision=fit.prior.precision, noise=fit.noise,
                 posterior=old, coordinates=measurement.angles / WORKSPACE, pure=E,
                 base=base.reported_combinations(names), base_old=base.combinations(names),
                 **({} if budget is None else {"model_error": budget.reshape(len(budget), -1)}))
    return {"scenario": scenario_name, "seed": seed, "trajectory": trajectory or "standard",
            "n_points": int(measurement.n_points), "fit_rms_urad": fit.rms * 1e6, "pure": pure,
            "z_sources_new": _z(fit.x, truth, fit.covariance, E).tolist(),
            "z_sources_old": _z(fit.x, truth, old, E).tolist(),
            "z_base_new": _z(fit.x, truth, fit.covariance, base.reported_combinations(names)).tolist(),
            "z_base_old": _z(fit.x, truth, old, base.combinations(names)).tolist(),
            **({} if fit.profile_bars is None else {  # the same bars without the profile's term (--profile-bars)
                "z_sources_no_profile": _z(fit.x, truth, fit.covariance - fit.profile_bars.added, E).tolist(),
                "z_base_no_profile": _z(fit.x, truth, fit.covariance - fit.profile_bars.added,
                                        base.reported_combinations(names)).tolist(),
                "profile_bars": fit.profile_bars.as_dict()}),
            "width_ratio": (np.sqrt(np.diag(E @ fit.covariance @ E.T)) / np.sqrt(np.diag(E @ old @ E.T))).tolist(),
            "abs_errors_si": errors, "walk_rms_urad": float(np.sqrt(np.mean(predicted ** 2)) * 1e6),
            "walk_seed": [walk_seed, seed], "model": list(model),
            "discrepancy": None if fit.discrepancy is None else fit.discrepancy.as_dict()}


def _rms(values) -> float:
    values = np.asarray(values, float)
    return float(np.sqrt(np.mean(values ** 2))) if values.size else float("nan")


def summarize(cases: list[dict]) -> None:
    print("| mount | trajectory | seeds | z RMS sources old -> new (n) | z RMS base old -> new (n) | "
          "width new/old (geo. mean) | fit RMS [urad] | walk RMS [urad] |")
    print("|---|---|---|---|---|---:|---:|---:|")
    groups: dict[tuple[str, str], list[dict]] = {}
    for case in cases:
        groups.setdefault((case["scenario"], "standard" if case["trajectory"] == "standard" else "designed"),
                          []).append(case)
    for (mount, kind), group in sorted(groups.items()):
        cat = lambda key: sum((c[key] for c in group), [])  # noqa: E731
        ratio = float(np.exp(np.mean(np.log(cat("width_ratio"))))) if cat("width_ratio") else float("nan")
        print(f"| {mount} | {kind} | {','.join(str(c['seed']) for c in group)} | "
              f"{_rms(cat('z_sources_old')):.3g} -> {_rms(cat('z_sources_new')):.3g} ({len(cat('z_sources_new'))}) | "
              f"{_rms(cat('z_base_old')):.3g} -> {_rms(cat('z_base_new')):.3g} ({len(cat('z_base_new'))}) | "
              f"{ratio:.3g} | {np.mean([c['fit_rms_urad'] for c in group]):.3g} | "
              f"{np.mean([c['walk_rms_urad'] for c in group]):.3g} |")
    print()
    print("| mount | seed | drive sources both identify alone | largest error standard / designed (mu: not scored) | "
          "n alone standard / designed | walk RMS standard / designed [urad] |")
    print("|---|---|---|---|---|---|")
    for case in cases:
        if case["trajectory"] != "standard":
            continue
        other = [c for c in cases if c["scenario"] == case["scenario"] and c["seed"] == case["seed"]
                 and c["trajectory"] != "standard"]
        if not other:
            continue
        d = other[0]
        both = [n for n in DRIVES if n in case["abs_errors_si"] and n in d["abs_errors_si"]]

        def worst(c, symbol):  # [um] the largest error over the x0 or the CL both identify alone
            return max((c["abs_errors_si"][n] * 1e6 for n in both if n.endswith(symbol)), default=float("nan"))

        print(f"| {case['scenario']} | {case['seed']} | {', '.join(both)} | x0 {worst(case, 'x0'):.3g} / "
              f"{worst(d, 'x0'):.3g} um, CL {worst(case, 'CL'):.3g} / {worst(d, 'CL'):.3g} um | "
              f"{len(case['pure'])} / {len(d['pure'])} | "
              f"{case['walk_rms_urad']:.3g} / {d['walk_rms_urad']:.3g} |")


def recompute_bars(out: Path) -> list[dict]:
    """The error bars of each saved fit (OUT/arrays/*.npz, written by run_case) recomputed with
    the Matern discrepancy alone (before issue 28's item 1), with the Matern + quadratic
    polynomial one (``fit_discrepancy``'s default) and, when the file holds a model-error
    budget (``model_error`` (K, 3n): run with --budget-draws, or added to an older fit's file),
    with that budget too ("budget"): same fit, same sandwich. Returns one row per fit with the
    z-scores and the bar widths."""
    from flexcal.calibration.discrepancy import fit_discrepancy, sandwich_covariance

    rows = []
    for path in sorted((out / "arrays").glob("*.npz")):
        a = dict(np.load(path))
        row = {"case": path.stem}
        variants = [("matern", False, None), ("polynomial", True, None)]
        if "model_error" in a:
            variants.append(("budget", True, a["model_error"]))
        for label, polynomial, model_error in variants:
            found = fit_discrepancy(a["residual"], a["jacobian"], a["x"], a["prior_mean"], a["prior_std"],
                                    a["coordinates"], polynomial=polynomial, model_error=model_error)
            cov = sandwich_covariance(a["posterior"], a["jacobian"], float(a["noise"]), a["prior_precision"],
                                      found.covariance)
            row[f"z_sources_{label}"] = _z(a["x"], a["truth"], cov, a["pure"]).tolist()
            row[f"z_base_{label}"] = _z(a["x"], a["truth"], cov, a["base"]).tolist()
            row[f"std_sources_{label}"] = np.sqrt(np.einsum("kd,de,ke->k", a["pure"], cov, a["pure"])).tolist()
            row[f"discrepancy_{label}"] = found.as_dict()
        rows.append(row)
        print(f"{path.stem}: z sources {np.round(row['z_sources_matern'], 2)} -> "
              f"{np.round(row['z_sources_polynomial'], 2)}; base RMS {_rms(row['z_base_matern']):.3g} -> "
              f"{_rms(row['z_base_polynomial']):.3g}; tau {row['discrepancy_polynomial']['polynomial_tau_urad']:.3g} "
              f"urad" + ("" if "z_base_budget" not in row else
                         f"; with the budget: z sources {np.round(row['z_sources_budget'], 2)}, base RMS "
                         f"{_rms(row['z_base_budget']):.3g} {np.round(row['z_base_budget'], 1)}"), flush=True)
    return rows


def summarize_recomputed(rows: list[dict]) -> None:
    """Pooled table of ``recompute_bars`` by mount and trajectory (case names scenario-seed-trajectory)."""
    print("| mount | trajectory | fits | z RMS sources Matern -> + polynomial (n) | z RMS base Matern -> + polynomial (n) "
          "| width + polynomial / Matern (geo. mean, sources) | with the budget: z RMS sources / base, width budget / "
          "polynomial (sources, base) |")
    print("|---|---|---|---|---|---:|---|")
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in rows:
        mount, seed, trajectory = row["case"].split("-", 2)
        groups.setdefault((mount, trajectory), []).append(row)
    for (mount, trajectory), group in sorted(groups.items()):
        cat = lambda key: sum((r[key] for r in group), [])  # noqa: E731
        ratio = np.asarray(cat("std_sources_polynomial")) / np.asarray(cat("std_sources_matern"))
        print(f"| {mount} | {trajectory} | {', '.join(r['case'] for r in group)} | "
              f"{_rms(cat('z_sources_matern')):.3g} -> {_rms(cat('z_sources_polynomial')):.3g} "
              f"({len(cat('z_sources_polynomial'))}) | {_rms(cat('z_base_matern')):.3g} -> "
              f"{_rms(cat('z_base_polynomial')):.3g} ({len(cat('z_base_polynomial'))}) | "
              f"{float(np.exp(np.mean(np.log(ratio)))) if ratio.size else float('nan'):.3g} | "
              + (_budget_cell(group) if all("z_base_budget" in r for r in group) else "-") + " |")


def _budget_cell(group: list[dict]) -> str:
    """z RMS sources / base with the budget and its bar widths against the polynomial ones
    (geometric means; a base parameter's width from |error| / |z|, the same error both times)."""
    cat = lambda key: np.asarray(sum((r[key] for r in group), []), float)  # noqa: E731
    sources = cat("std_sources_budget") / cat("std_sources_polynomial")
    base = np.abs(cat("z_base_polynomial")) / np.maximum(np.abs(cat("z_base_budget")), 1e-300)
    geo = lambda v: float(np.exp(np.mean(np.log(v)))) if v.size else float("nan")  # noqa: E731
    return (f"{_rms(cat('z_sources_budget')):.3g} / {_rms(cat('z_base_budget')):.3g}, widths "
            f"{geo(sources):.3g}, {geo(base):.3g}")


def main(argv=None) -> int:
    from flexcal.validation.prototype.providers import stiffness_provider

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True)
    parser.add_argument("--scenarios", default="table1,paper")
    parser.add_argument("--seeds", default="1,2,3")
    parser.add_argument("--designs", default="", help="scenario=trajectory.csv,... (flexcal design's)")
    parser.add_argument("--provider", default="fem", choices=("fem", "analytic"))
    parser.add_argument("--noise-urad", type=float, default=0.5)
    parser.add_argument("--walk-seed", type=int, default=101)
    parser.add_argument("--summary-only", action="store_true")
    parser.add_argument("--recompute-bars", action="store_true",
                        help="only recompute the bars of the saved fits (OUT/arrays) with the Matern discrepancy "
                             "alone and with the polynomial part; writes OUT/recomputed.json")
    parser.add_argument("--model", default="second-order", choices=("paper", "second-order", "consistent"))
    parser.add_argument("--model-stiffness", default="fem", choices=("fem", "closed-form"))
    parser.add_argument("--no-second-order", action="store_true")
    parser.add_argument("--budget-draws", type=int, default=None, metavar="K",
                        help="give identify_all the model-error budget flexcal verify computes (the estimate, K "
                             "prior draws: validation/runs/error_budget.py); default: none (the fit "
                             "does not depend on it; --recompute-bars scores it on the saved fits)")
    parser.add_argument("--profile-bars", action="store_true",
                        help="widen the base combinations' bars by their profile likelihood (calibration/"
                             "profile_bars.py; flexcal verify's default for --model consistent); the cases record the "
                             "z-scores without that term too")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "cases.jsonl"
    cases = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    designs = dict(item.split("=", 1) for item in args.designs.split(",") if item)
    if args.recompute_bars:
        rows = recompute_bars(out)
        (out / "recomputed.json").write_text(json.dumps(rows, indent=1))
        summarize_recomputed(rows)
        return 0
    if not args.summary_only:
        provider = stiffness_provider(args.provider, progress=False, workers=None)
        for name in args.scenarios.split(","):
            for seed in (int(s) for s in args.seeds.split(",")):
                for trajectory in [None] + ([designs[name]] if name in designs else []):
                    key = (name, seed, trajectory or "standard")
                    if any((c["scenario"], c["seed"], c["trajectory"]) == key for c in cases):
                        continue
                    case = run_case(name, seed, trajectory, provider, args.noise_urad, args.walk_seed,
                                    (args.model, args.model_stiffness, not args.no_second_order), out / "arrays",
                                    args.budget_draws, args.profile_bars)
                    cases.append(case)
                    with log.open("a") as handle:
                        handle.write(json.dumps(case) + "\n")
                    if "z_base_no_profile" in case:
                        print(f"{key}: base z RMS without the profile {_rms(case['z_base_no_profile']):.3g}, with "
                              f"{_rms(case['z_base_new']):.3g}; sources {_rms(case['z_sources_no_profile']):.3g}, "
                              f"{_rms(case['z_sources_new']):.3g}", flush=True)
                    print(f"{key}: z sources {np.round(case['z_sources_old'], 2)} -> "
                          f"{np.round(case['z_sources_new'], 2)}, base RMS {_rms(case['z_base_old']):.3g} -> "
                          f"{_rms(case['z_base_new']):.3g}, walk {case['walk_rms_urad']:.3g} urad", flush=True)
    summarize(cases)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
