"""``flexcal truth``: synthetic misalignment curves from the virtual prototype.

Writes ``DIR/curves.csv`` (the measurement format), ``DIR/curves.json`` (provenance: the
scenario, every preset error, injected effects, solver residuals) and
``DIR/curves.png`` (the three misalignment curves, measured minus the ideal
small-deflection model, each point coloured by its class S1/S2/S3).
"""

from __future__ import annotations

import argparse

import numpy as np

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", required=True,
                        help="built-in scenario (table1, nominal) or a scenario TOML file")
    parser.add_argument("--seed", type=int, default=None, help="seed for drawn errors and sensor noise")
    parser.add_argument("--noise-urad", type=float, default=None,
                        help="sensor noise standard deviation per channel [urad] (default: the scenario's; table1: 0)")
    parser.add_argument("--provider", choices=("fem", "analytic"), default="fem",
                        help="segment stiffness: FEM condensation of the as-built solids (default) or the "
                             "closed-form compliance (fast, for checks only: then truth shares the model's hinge formulas)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--quiet", action="store_true", help="no progress output")


def stiffness_provider(kind: str, *, progress: bool = True):
    """The segment stiffness provider by name."""
    if kind == "analytic":
        from .segments import analytic_provider

        return analytic_provider()
    from .fem_provider import fem_provider

    return fem_provider(progress=progress)


def run(args: argparse.Namespace) -> int:
    from flexcal.model.forward import ideal_angles

    from .measurements import write_measurement
    from .output import staged_output
    from .plots import plot_misalignment_curves
    from .scenario import load_scenario
    from .truth import make_truth

    if args.noise_urad is not None and args.noise_urad < 0:
        raise ValueError(f"--noise-urad={args.noise_urad} must be >= 0")
    scenario = load_scenario(args.scenario, seed=args.seed, noise_urad=args.noise_urad)
    provider = stiffness_provider(args.provider, progress=not args.quiet)
    result = make_truth(scenario, provider, progress=not args.quiet)
    measurement = result.measurement
    misalignment = measurement.angles - ideal_angles(measurement.inputs, scenario.space)
    with staged_output(args.out) as staging:
        write_measurement(staging / "curves.csv", measurement)
        plot_misalignment_curves(staging / "curves.png", misalignment, result.run.point_class, leg=measurement.leg,
                                 title=f"virtual prototype, scenario {scenario.name} (seed {scenario.seed}): "
                                       f"measured − ideal model")
    classes, counts = np.unique(result.run.point_class, return_counts=True)
    print(f"flexcal truth: {measurement.n_points} points, classes "
          + ", ".join(f"{c} {n}" for c, n in zip(classes, counts))
          + f"; max |misalignment| = {', '.join(f'{v:.1f}' for v in np.abs(misalignment).max(axis=0) * 1e6)} urad; "
          f"max residual {np.max(result.run.force_residual):.1e} N; wrote {args.out}/curves.csv, curves.json, curves.png")
    return 0
