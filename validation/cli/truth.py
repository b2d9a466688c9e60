"""``flexcal truth``: synthetic misalignment curves from the virtual prototype.

Writes ``DIR/curves.csv`` (the measurement format, with the room temperature as column
``temperature_c``), ``DIR/curves.json`` (provenance: the scenario, every preset error, the
injected effects of its ``[[effects]]`` tables, solver residuals) and
``DIR/curves.png`` (the three misalignment curves, measured minus the ideal
small-deflection model, each point coloured by its class S1/S2/S3).
"""

from __future__ import annotations

import argparse

import numpy as np

from ..prototype.providers import PROVIDERS
from .options import add_mount, add_out, add_scenario, add_seed, add_trajectory

__all__ = ["configure", "run", "EXAMPLES", "DEFAULT_CONFIG"]

EXAMPLES = (
    "flexcal truth --scenario table1 --out runs/truth                      # FEM prototype, ~5 s with a warm cache",
    "flexcal truth --scenario table1 --provider analytic --seed 3 --out runs/quick",
    "flexcal truth --scenario my-mount.toml --noise-urad 0.5 --out runs/noisy",
    "flexcal truth --scenario paper --trajectory runs/design/trajectory.csv --noise-urad 0.5 --out runs/paper",
    "flexcal truth --scenario table1 --mount my.mount.toml --out runs/mine   # the Table 1 presets on your mount",
)
DEFAULT_CONFIG = {"provider": "fem"}


def configure(parser: argparse.ArgumentParser) -> None:
    add_scenario(parser)
    add_seed(parser, what="drawn errors and sensor noise (default: the scenario's)")
    parser.add_argument("--noise-urad", type=float, default=None,
                        help="sensor noise standard deviation per channel [urad] (default: the scenario's; table1: 0)")
    parser.add_argument("--provider", choices=PROVIDERS,
                        help="segment stiffness: FEM condensation of the as-built segments on the mapped mesh, "
                             "each chain's segments joined through section fields at its cuts (fem, the default; "
                             "docs/meshing.md), the same joined rigidly (fem-rigid: the chains 19-23 %% too stiff "
                             "axially, for comparison), rigidly joined segments on fTetWild meshes (fem-tetwild) "
                             "or the closed-form compliance "
                             "(fast, for checks only: then truth shares the model's hinge formulas)")
    add_trajectory(parser)
    add_mount(parser)
    from .options import add_executor_options

    add_executor_options(parser, what="the FEM segment builds (cold cache only)")
    add_out(parser, what="curves.csv, curves.json, curves.png")


def run(args: argparse.Namespace) -> int:
    from flexcal.model.forward import ideal_angles

    from ..measurements import write_measurement
    from ..output import staged_output, write_report
    from ..reports.truth import truth_markdown, write_truth_figure
    from .options import load_scenario_with_trajectory
    from ..prototype.truth import make_truth

    if args.noise_urad is not None and args.noise_urad < 0:
        raise ValueError(f"--noise-urad={args.noise_urad} must be >= 0")
    scenario = load_scenario_with_trajectory(args)
    from .options import executor_options

    from ..prototype.providers import stiffness_provider

    provider = stiffness_provider(args.provider, progress=not args.quiet, **executor_options(args))
    result = make_truth(scenario, provider, progress=not args.quiet)
    measurement = result.measurement
    misalignment = measurement.angles - ideal_angles(measurement.inputs, scenario.space)
    classes, counts = np.unique(result.run.point_class, return_counts=True)
    injected = [e["name"] for e in result.run.provenance.get("effects", [])]
    max_misalignment = np.abs(misalignment).max(axis=0) * 1e6
    report = {
        "summary": {"n_points": int(measurement.n_points), "scenario": scenario.name, "seed": int(scenario.seed),
                    "effects": injected, **{f"n_{c}": int(n) for c, n in zip(classes, counts)},
                    **{f"max_misalignment_{a}_urad": float(v) for a, v in zip(("theta_x", "theta_y", "theta_z"),
                                                                                max_misalignment)},
                    "max_force_residual_n": float(np.max(result.run.force_residual))},
        "metadata": measurement.metadata,
        "wall_s": float(result.run.wall_time),
    }
    with staged_output(args.out, replace=args.force) as staging:
        write_measurement(staging / "curves.csv", measurement)
        write_report(staging, report)
        (staging / "report.md").write_text(truth_markdown(scenario, measurement.n_points, classes, counts, injected,
                                                          max_misalignment))
        write_truth_figure(staging, scenario, misalignment, result.run.point_class, measurement.leg)
    print(f"flexcal truth: {measurement.n_points} points, "
          + (f"effects {', '.join(injected)}, " if injected else "") + "classes "
          + ", ".join(f"{c} {n}" for c, n in zip(classes, counts))
          + f"; max |misalignment| = {', '.join(f'{v:.1f}' for v in np.abs(misalignment).max(axis=0) * 1e6)} urad; "
          f"max residual {np.max(result.run.force_residual):.1e} N; wrote {args.out}/curves.csv, curves.json, curves.png, "
          "report.json, report.md")
    return 0
