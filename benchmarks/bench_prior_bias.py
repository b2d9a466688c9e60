"""Which prior-held sources bias a base combination, on noise-free data (issue #28, a diagnostic).

    .venv/bin/python benchmarks/bench_prior_bias.py --scenario table1 --seed 2 \
        [--trajectory runs/design/trajectory.csv] [--start runs/std/report.json] [--noise-urad 0.5] \
        [--model consistent] [--dimension-terms quadratic] [--own-curve]

The virtual prototype's noise-free curve (or with ``--own-curve`` the calibration model's own
curve at the true values: no form error either) is identified by ``identify_all`` with the
sensor noise *given* (``--noise-urad``): the estimate a noisy measurement's prior weighting
gives, without any noise. Every base combination's error is then printed in its linear standard
errors (z), at the estimate and after refits with one group of sources (a chain's five leaf
dimensions, the mount offsets, ...) held at the truth (their prior's mean moved onto the true
values with a std of 1e-4 of the range, every other source re-optimised). A combination whose z
falls when a group is held is biased by that group's prior-held coordinates through the model's
nonlinearity; one whose z stays is not. Also printed: each chain's stiffness score of the truth,
``(w + t1 + t2 - l) / 2`` of its unit-box draws in the prior's standard deviations (the
direction all four stiffen the chain in; a sum of four uniform draws, so |score| <= 3.46 and
|score| > 2.6 in 0.52 % of draws, simulated).

Reads the true values: a diagnostic of the estimator, never a method. Not a test (a consistent
identification on the FEM prototype takes minutes); the figures go into docs/calibration.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

import numpy as np

DIMENSIONS = ("w", "a", "l", "t1", "t2")


def groups(names: list[str]) -> dict[str, list[str]]:
    """The source groups held at the truth one at a time."""
    chains = sorted({n.split(".")[0] for n in names if n.split(".")[1] in DIMENSIONS})
    found = {f"{c} dims": [f"{c}.{k}" for k in DIMENSIONS if f"{c}.{k}" in names] for c in chains}
    found["offsets"] = [n for n in names if n.endswith((".dy", ".dz"))]
    found["drives"] = [n for n in names if n.split(".")[1] in ("x0", "CL", "mu")]
    found["every dim"] = [n for n in names if n.split(".")[1] in DIMENSIONS]
    return found


def stiffness_scores(space, values: np.ndarray) -> dict[str, float]:
    """Each chain's ``(w + t1 + t2 - l) / 2`` of the true values' unit-box positions, in the
    prior's standard deviations (range / sqrt 12)."""
    names = list(space.names)
    z = (space.to_unit(values[space.active_indices]) - 0.5) * np.sqrt(12.0)
    chains = sorted({n.split(".")[0] for n in names if n.split(".")[1] in DIMENSIONS})
    return {c: float((z[names.index(f"{c}.w")] + z[names.index(f"{c}.t1")] + z[names.index(f"{c}.t2")]
                      - z[names.index(f"{c}.l")]) / 2.0) for c in chains}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="table1")
    parser.add_argument("--seed", type=int, default=2)
    parser.add_argument("--trajectory", default=None, help="flexcal design's trajectory.csv (default: standard)")
    parser.add_argument("--start", default=None, help="a report.json whose identified values every fit starts from")
    parser.add_argument("--noise-urad", type=float, default=0.5, help="the noise given to the estimator [urad]")
    parser.add_argument("--model", default="consistent")
    parser.add_argument("--dimension-terms", default="quadratic", choices=("linear", "quadratic"))
    parser.add_argument("--own-curve", action="store_true", help="fit the model's own curve at the true values")
    args = parser.parse_args(argv)

    from flexcal.calibration.estimation import FD_STEP, Prior, fit_evaluations, map_objective_rows
    from flexcal.calibration.pipeline import IdentificationSettings, identify_all
    from flexcal.calibration.polish import least_squares_polish
    from flexcal.validation.measurements import read_trajectory
    from flexcal.validation.prototype.fem_provider import fem_provider
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import make_truth
    from flexcal.validation.runs.dimension_terms import curved_space
    from flexcal.validation.runs.model_correction import model_space

    scenario = load_scenario(args.scenario, seed=args.seed, noise_urad=0.0)
    if args.trajectory:
        inputs, leg = read_trajectory(args.trajectory)
        scenario = dataclasses.replace(scenario, inputs=inputs, leg=leg)
    provider = fem_provider()
    measurement = make_truth(scenario, provider).measurement
    space = model_space("fem", True, mechanism=scenario.space.mechanism, model=args.model)
    if args.dimension_terms == "quadratic":
        space = curved_space(space, provider)
    start = None
    if args.start:
        rows = json.load(open(args.start))["parameters"]
        start = space.build_values({r["name"]: r["identified"] for r in rows}, display_units=True)
    angles = measurement.angles
    from flexcal.calibration.problem import CalibrationProblem
    from flexcal.model.trajectory import travel_directions

    problem = CalibrationProblem(space=space, inputs=measurement.inputs, angles=angles,
                                 directions=travel_directions(measurement.inputs))
    x_true_space = space.to_unit(scenario.values[space.active_indices])
    if args.own_curve:
        angles = problem.model_angles(x_true_space[None])[0][0]
        problem = dataclasses.replace(problem, angles=angles)
    found = identify_all(space, measurement.inputs, angles, measurement.leg,
                         IdentificationSettings(noise=args.noise_urad * 1e-6, start=start))
    chart, fit = found.chart, found.estimate
    names = list(chart.names)
    truth = chart.from_space(x_true_space)
    C = found.base.reported_combinations(names)
    linear_std = np.sqrt(np.einsum("kd,de,ke->k", C, fit.covariance, C))
    labels = list(found.base.base)
    print(f"{args.scenario} seed {args.seed}, {'the model own curve' if args.own_curve else 'the prototype'} "
          f"noise-free, noise given {args.noise_urad} urad; fit {fit.rms * 1e6:.3g} urad; z of the base "
          f"combinations (named by their leading source) in their linear standard errors")
    print("| held at the truth | " + " | ".join(labels) + " |")
    print("|---|" + "---:|" * len(labels))

    def row(tag: str, x: np.ndarray) -> None:
        print(f"| {tag} | " + " | ".join(f"{v:+.2f}" for v in C @ (x - truth) / linear_std) + " |", flush=True)

    row("none (the estimate)", fit.x)
    residuals = lambda Y: problem.residuals(chart.to_space(Y))  # noqa: E731
    for tag, members in groups(names).items():
        held = np.isin(names, members)
        prior = Prior(mean=np.where(held, truth, fit.prior.mean), std=np.where(held, 1e-4, fit.prior.std))
        refit = least_squares_polish(map_objective_rows(residuals, prior, fit.noise), np.where(held, truth, fit.x),
                                     fd_step=FD_STEP, ftol=1e-10, xtol=1e-10, gtol=1e-10,
                                     max_evaluations=fit_evaluations(len(names)))
        row(tag, refit.x)
    scores = stiffness_scores(space, scenario.values)
    print("\nthe truth's chain stiffness scores (w + t1 + t2 - l) / 2 [prior std]: "
          + ", ".join(f"{c} {s:+.2f}" for c, s in scores.items()))


if __name__ == "__main__":
    sys.exit(main())
