"""``flexcal inverse``: the analytic model's inputs for target angles at one posture.

    flexcal inverse --target-urad 100,-500,200 [--directions +1,+1,+1] [--params FILE] [--json] [--out DIR]

Targets are the absolute angles theta_x, theta_y, theta_z [urad] relative to the unloaded
design pose (the gravity sag is part of them; docs/conventions.md). A negative first value
needs the ``=`` form: ``--target-urad=-100,0,0``.
"""

from __future__ import annotations

import argparse

from .options import add_point_model_options
from .forward import (load_values, parse_directions, parse_triple, point_report, print_point, write_point)
from ..output import dumps_strict

__all__ = ["configure", "run", "EXAMPLES"]

EXAMPLES = (
    "flexcal inverse --target-urad 100,-500,200",
    "flexcal inverse --target-urad=-100,0,0 --params errors.toml --json",
    "flexcal inverse --target-urad 100,-500,200 --out runs/inverse",
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--target-urad", required=True, metavar="TX,TY,TZ",
                        help="target angles theta_x,theta_y,theta_z [urad]; use --target-urad=-100,0,0 for a "
                             "negative first value")
    add_point_model_options(parser)


def run(args: argparse.Namespace) -> int:
    from flexcal.model.clearance import ConvergenceError
    from flexcal.model.inverse import inverse

    target = parse_triple(args.target_urad, "--target-urad") * 1e-6
    directions = parse_directions(args.directions)
    from .options import mount_option

    space, values, overrides = load_values(args.params, mount_option(args))
    try:
        result = inverse(target[None, :], None if directions is None else directions[None, :], space_values=values,
                         space=space, parasitic=not args.no_parasitic, clearance=not args.no_clearance,
                         clearance_mode=args.clearance_mode)
    except ConvergenceError as error:
        raise ValueError(f"the inverse did not converge: {error}") from None
    report = point_report(result.forward, 0, overrides)
    report["target_urad"] = (target * 1e6).tolist()
    report["residual_urad"] = (result.residual[0] * 1e6).tolist()
    residual_line = "  angle residual [urad]: " + ", ".join(f"{v:.2e}" for v in report["residual_urad"])
    if args.out:
        write_point(args.out, report, "flexcal inverse (analytic model, paper Eq. 1-8)", (residual_line,), replace=args.force)
    if args.json:
        print(dumps_strict(report))
    else:
        print_point(report, "flexcal inverse (analytic model, paper Eq. 1-8)")
        print(residual_line)
    return 0
