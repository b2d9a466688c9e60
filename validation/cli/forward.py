"""``flexcal forward``: the analytic model at one posture (inputs -> pose, chain states, class).

    flexcal forward --inputs-mm 0.5,0,0 [--directions +1,+1,+1] [--params FILE] [--json] [--out DIR]

Inputs are the commanded actuator displacements x_A1..x_A3 [mm] (positive pushes the
payload frame); a negative first value needs the ``=`` form: ``--inputs-mm=-0.5,0,0``.
``--params`` is a TOML or JSON file of error sources in display units (docs/parameters.md).
With ``--out DIR`` the point is also written as DIR/report.json and DIR/report.md.
"""

from __future__ import annotations

import argparse

import numpy as np

from .options import add_point_model_options

from ..output import dumps_strict

__all__ = ["configure", "run", "parse_triple", "parse_directions", "load_values",
           "point_report", "print_point", "write_point", "EXAMPLES"]

EXAMPLES = (
    "flexcal forward --inputs-mm 0.5,0,0",
    "flexcal forward --inputs-mm=-0.4,0.2,0.1 --directions=-1,1,1 --params errors.toml --json",
    "flexcal forward --inputs-mm 0.5,0,0 --out runs/forward      # report.json + report.md",
)


def parse_triple(text: str, what: str) -> np.ndarray:
    """"a,b,c" -> (3,) floats; ``ValueError`` naming ``what`` otherwise."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        values = np.array([float(p) for p in parts])
    except ValueError:
        raise ValueError(f"{what} must be three comma-separated numbers, got {text!r}") from None
    if values.shape != (3,) or not np.all(np.isfinite(values)):
        raise ValueError(f"{what} must be three finite comma-separated numbers, got {text!r}")
    return values


def parse_directions(text: str | None) -> np.ndarray | None:
    if text is None:
        return None
    values = parse_triple(text, "--directions")
    if not np.all(np.abs(values) == 1.0):
        raise ValueError(f"--directions must be +1 or -1 for each actuator, got {text!r}")
    return values


def load_values(path: str | None, mount=None):
    """(space, (45,) SI values, overrides in display units) from ``--params`` on ``mount``
    (``MechanismParams``, ``--mount``; the reference mount without)."""
    from flexcal.model.param_file import read_parameter_file
    from flexcal.model.parameters import parameter_space

    space = parameter_space(mount)
    overrides = read_parameter_file(path) if path else {}
    return space, space.build_values(overrides, display_units=True), overrides


def point_report(result, point: int = 0, overrides: dict | None = None) -> dict:
    """JSON-ready summary of one point of a ``ForwardResult`` (candidate 0)."""
    from flexcal.model.forward import CLASS_NAMES, STATE_NAMES

    pose = result.pose[0, point]
    loads = result.axial_loads[0, point]
    chains = ("L1", "L2", "L3", "D1", "D2", "D3")
    return {
        "theta_urad": (pose[3:] * 1e6).tolist(),
        "inputs_mm": (result.inputs[point] * 1e3).tolist(),
        "point_class": CLASS_NAMES[int(result.point_class[0, point])],
        "chain_states": {f"D{i + 1}": STATE_NAMES[int(s)] for i, s in enumerate(result.chain_states[0, point])},
        "displacement_um": (pose[:3] * 1e6).tolist(),
        "directions": result.directions[point].astype(int).tolist(),
        "axial_load_N": {name: float(v) for name, v in zip(chains, loads)},
        "axial_sign": {name: ("tension" if v > 0 else "compression") for name, v in zip(chains, loads)},
        "clearance_um": {f"D{i + 1}": float(v * 1e6) for i, v in enumerate(result.clearance[0, point])},
        "release_fx_um": {f"D{i + 1}": float(v * 1e6) for i, v in enumerate(result.release[0, point])},
        "parasitic_um": {name: float(v * 1e6) for name, v in zip(chains, result.parasitic[0, point])},
        "params": dict(overrides or {}),
    }


def print_point(report: dict, title: str) -> None:
    print(title)
    print("  theta_x, theta_y, theta_z [urad]: " + ", ".join(f"{v:.4f}" for v in report["theta_urad"]))
    print("  dx, dy, dz [um]:                  " + ", ".join(f"{v:.4f}" for v in report["displacement_um"]))
    print("  inputs x_A1..x_A3 [mm]:           " + ", ".join(f"{v:.6f}" for v in report["inputs_mm"])
          + "   directions " + " ".join(f"{d:+d}" for d in report["directions"]))
    print("  chain   axial load [N]   state        C [um]     fx [um]   parasitic r [um]")
    for name, load in report["axial_load_N"].items():
        if name.startswith("D"):
            extra = (f"{report['chain_states'][name]:<10} {report['clearance_um'][name]:10.3f} "
                     f"{report['release_fx_um'][name]:11.3f}")
        else:
            extra = f"{'(load)':<10} {'':10} {'':11}"
        print(f"  {name:<6} {load:14.2f}   {extra} {report['parasitic_um'][name]:14.5f}")
    print(f"  point class: {report['point_class']} (S1 all driving chains compressed, S2 a chain in clearance, "
          f"S3 mixed, no clearance)")


def write_point(out: str, report: dict, title: str, extra_lines: tuple[str, ...] = (), *,
                replace: bool = False) -> None:
    """DIR/report.json (``report``) and DIR/report.md (the text output), whole or not at all
    (``replace``: --force, see ``output.staged_output``)."""
    import contextlib
    import io

    from ..output import staged_output, write_report
    from ..reports.forward import plot_point

    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        print_point(report, title)
        for line in extra_lines:
            print(line)
    with staged_output(out, replace=replace) as staging:
        write_report(staging, report)
        plot_point(report, staging / "point.png", title)
        (staging / "report.md").write_text(f"# {title}\n\n```\n{text.getvalue()}```\n\n![the point](point.png)\n")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--inputs-mm", required=True, metavar="X1,X2,X3",
                        help="actuator inputs x_A1,x_A2,x_A3 [mm]; use --inputs-mm=-0.5,0,0 for a negative first value")
    add_point_model_options(parser)


def run(args: argparse.Namespace) -> int:
    from flexcal.model.clearance import ConvergenceError
    from flexcal.model.forward import forward

    inputs = parse_triple(args.inputs_mm, "--inputs-mm") * 1e-3
    directions = parse_directions(args.directions)
    from .options import mount_option

    space, values, overrides = load_values(args.params, mount_option(args))
    try:
        result = forward(values, inputs[None, :], None if directions is None else directions[None, :], space=space,
                         parasitic=not args.no_parasitic, clearance=not args.no_clearance,
                         clearance_mode=args.clearance_mode)
    except ConvergenceError as error:
        raise ValueError(f"the model did not converge: {error}") from None
    report = point_report(result, 0, overrides)
    if args.out:
        write_point(args.out, report, "flexcal forward (analytic model, paper Eq. 1-8)", replace=args.force)
    if args.json:
        print(dumps_strict(report))
    else:
        print_point(report, "flexcal forward (analytic model, paper Eq. 1-8)")
    return 0
