"""The ``flexcal`` command line.

Each sub-command lives in its own module ``flexcal.validation.cmd_<name>`` exposing
``configure(parser)`` (adds its arguments) and ``run(args) -> int``. The module is
imported only when its command runs, so ``flexcal --help`` stays fast and a command
never pays for another's heavy imports (CadQuery, pyvista).

Errors the user can fix (``ValueError``, ``FileNotFoundError``) print one line on
stderr and exit with status 2; commands write their outputs only after the work
succeeded (see ``flexcal.validation.output``), so a failed run leaves nothing partial.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys

__all__ = ["main", "COMMANDS"]

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "hinge": ("cmd_hinge", "FEM vs closed-form 6x6 compliance of one flexure hinge"),
    "chain": ("cmd_chain", "FEM vs analytic 12x12 stiffness of one flexure chain"),
    "forward": ("cmd_forward", "analytic model: actuator inputs -> pose, chain states, point class"),
    "inverse": ("cmd_inverse", "analytic model: target angles -> actuator inputs"),
    "truth": ("cmd_truth", "virtual prototype: synthetic misalignment curves with preset errors"),
    "verify": ("cmd_verify", "Section 3.3 regression run: truth -> Sobol -> identification -> report"),
    "compensate": ("cmd_compensate", "closed-loop compensation and Table 2-3 style report"),
    "diagnose": ("cmd_diagnose", "sim-to-real gap diagnosis of a measurement file"),
    "diagnose-benchmark": ("cmd_diagnose_benchmark", "blind benchmark of the gap diagnosis"),
}


def _available() -> dict[str, tuple[str, str]]:
    found = {}
    for name, (module, text) in COMMANDS.items():
        if importlib.util.find_spec(f"flexcal.validation.{module}") is not None:
            found[name] = (module, text)
    return found


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; with ``only`` set, only that sub-command is configured."""
    parser = argparse.ArgumentParser(
        prog="flexcal",
        description="flexcal: finite-element verification of flexure-based precision adjustment "
        "mechanisms (error model, calibration and sim-to-real diagnosis of a heavy-optics mount).",
        epilog="Run 'flexcal <command> --help' for the options of a command.",
    )
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    for name, (module, text) in _available().items():
        command_parser = sub.add_parser(name, help=text, description=text)
        if name == only:
            importlib.import_module(f"flexcal.validation.{module}").configure(command_parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(only=command if command in COMMANDS else None)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    module = importlib.import_module(f"flexcal.validation.{COMMANDS[args.command][0]}")
    try:
        return int(module.run(args) or 0)
    except (ValueError, FileNotFoundError) as error:
        print(f"flexcal {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
