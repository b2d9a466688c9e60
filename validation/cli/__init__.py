"""The ``flexcal`` command line.

Each sub-command lives in its own module ``flexcal.validation.cli.<name>`` exposing
``configure(parser)`` (adds its arguments) and ``run(args) -> int``, and optionally
``EXAMPLES`` (command lines shown in its ``--help``) and ``DEFAULT_CONFIG`` (TOML-able
settings, giving it ``--config FILE`` and ``--print-config``). The module is imported
only when its command runs, so ``flexcal --help`` stays fast and a command never pays
for another's heavy imports (CadQuery, pyvista). The options every command shares
(``-v/-q``, ``--debug``, ``--json``, ``--config``) are added here
(``flexcal.validation.cli.common``; the convention: docs/cli.md).

Errors about the input (``ValueError``, ``OSError``, a solver or mesher that fails,
a bad option) print one line on stderr and exit with status 2; Ctrl-C exits 130, SIGTERM
143 (one line; staging folders removed: ``flexcal.validation.cli.signals``); a bug
prints one line and exits 1; ``--debug`` adds the traceback. Commands write their outputs
only after the work succeeded (``flexcal.validation.output``), so a failed or
interrupted run leaves nothing partial. Before a command runs, ``--out`` is reserved for
it until it ends (``flexcal.validation.out_lock``: a second run to the same folder is
refused) and checked (``flexcal.validation.run_folder``: ``--force`` only on a run folder
that holds none of the command's inputs), and an option that takes a file but was given
a folder is refused. Once the command has returned, Ctrl-C and SIGTERM are held back
until the process has ended (``_hold_back_late_signals``). Called in-process with an
``argv`` (a test, a script), a real Ctrl-C or SIGTERM that stopped the command is passed
on to the caller once the command has cleaned up (``_pass_on_signal``): it stops pytest
or the script as it would have without flexcal, rather than ending one call with 130/143.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import importlib.util
import os
import re
import sys
import traceback

__all__ = ["main", "COMMANDS", "build_parser"]

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "hinge": ("hinge", "FEM vs closed-form 6x6 compliance of one flexure hinge"),
    "chain": ("chain", "FEM vs analytic 12x12 stiffness of one flexure chain"),
    "forward": ("forward", "analytic model: actuator inputs -> pose, chain states, point class"),
    "inverse": ("inverse", "analytic model: target angles -> actuator inputs"),
    "design": ("design", "choose calibration postures (D-optimal) and write a trajectory file"),
    "truth": ("truth", "virtual prototype: synthetic misalignment curves with preset errors"),
    "sensitivity": ("sensitivity", "Sobol screening of the 45 error sources on a measurement or scenario"),
    "identify": ("identify", "identify error sources from a measurement (improved PSO + polish)"),
    "verify": ("verify", "Section 3.3 regression run: truth -> Sobol -> identification -> report"),
    "compensate": ("compensate", "closed-loop compensation and Table 2-3 style report"),
    "diagnose": ("diagnose", "sim-to-real gap diagnosis of a measurement file"),
    "diagnose-benchmark": ("diagnose_benchmark", "blind benchmark of the gap diagnosis"),
    "sweep": ("sweep", "FEM vs closed form over a grid or Latin hypercube of hinge/chain dimensions, locally or on Dask"),
    "report": ("report", "turn a run folder into one self-contained HTML page"),
    "structure": ("structure", "the mount as a structure: modes, support stiffness, stress vs yield, buckling"),
    "mount": ("mount", "print an example mount file, or check one (--mount FILE of the other commands)"),
}


# A number, and a comma list of numbers, starting with a minus sign: an option's value, not
# an option ('--target-urad -100,200,50'). argparse knows only single numbers ('-5', '-.5').
_NUMBER = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
_NEGATIVE_NUMBERS = re.compile(rf"^-{_NUMBER}(\s*,\s*[-+]?{_NUMBER})*$")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors ('flexcal hinge: error: ...', exit 2) and with
    values such as '-100,200,50' taken as values (no '=' needed)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # argparse's own hook for "looks like a negative number" (used while no option
        # of the parser itself looks like one); widened from single numbers to lists
        self._negative_number_matcher = _NEGATIVE_NUMBERS

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def _available() -> dict[str, tuple[str, str]]:
    found = {}
    for name, (module, text) in COMMANDS.items():
        if importlib.util.find_spec(f"flexcal.validation.cli.{module}") is not None:
            found[name] = (module, text)
    return found


def _description(text: str, module) -> str:
    doc = (module.__doc__ or "").replace("``", "").strip()
    body = doc.split("\n\n", 1)[1] if "\n\n" in doc else ""
    return f"{text}.\n\n{body}".rstrip()


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; with ``only`` set, only that sub-command is configured."""
    from .common import examples_epilog, install_common_options

    parser = _Parser(
        prog="flexcal",
        description="flexcal: finite-element verification of flexure-based precision adjustment "
        "mechanisms (error model, calibration and sim-to-real diagnosis of a heavy-optics mount).",
        epilog="Run 'flexcal <command> --help' for the options and examples of a command; "
               "'flexcal <command> --print-config' for its settings. Start with: "
               "flexcal verify --scenario table1 --out runs/table1 && flexcal report runs/table1",
    )
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    for name, (module_name, text) in _available().items():
        if name != only:
            sub.add_parser(name, help=text, description=text)
            continue
        module = importlib.import_module(f"flexcal.validation.cli.{module_name}")
        command_parser = sub.add_parser(name, help=text, description=_description(text, module),
                                        epilog=examples_epilog(module),
                                        formatter_class=argparse.RawDescriptionHelpFormatter)
        module.configure(command_parser)
        install_common_options(command_parser, module)
    return parser


def _command_of(argv: list[str]) -> str | None:
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: list[str] | None = None) -> int:
    from_sys_argv = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    command = _command_of(argv)
    if command is not None and command not in COMMANDS:
        print(f"flexcal: error: unknown command {command!r}; 'flexcal --help' lists them", file=sys.stderr)
        return 2
    status = _run(argv, command, hold_back=from_sys_argv)  # the process ends next (not a test's or a script's)
    if from_sys_argv:
        _hold_back_late_signals()  # again: leaving termination_raises put the handlers back
    else:
        _pass_on_signal()
    return status


def _pass_on_signal() -> None:
    """Deliver a Ctrl-C or SIGTERM that stopped an in-process command again, now to the
    caller's own handler (put back by ``termination_raises``): pytest stops on it, a default
    SIGTERM ends the process. Before, a SIGTERM to a pytest run only failed the test that
    was inside ``main`` (status 143) and the run went on: it took a SIGKILL to stop it."""
    import signal

    from ..interrupts import take_received

    signum = take_received()  # the first signal of the last termination_raises block
    if signum is not None:
        signal.raise_signal(signum)


def _run(argv: list[str], command: str | None, *, hold_back: bool = False) -> int:
    from ..interrupts import raise_received
    from ..out_lock import held_folders, release_left
    from ..output import written_folders
    from .signals import termination_raises

    debug = "--debug" in argv
    n_written_before = len(written_folders())
    held_before = held_folders()
    try:
        with termination_raises():
            status = _main(argv, command)
            raise_received()  # one a library swallowed on the way (interrupts' module doc)
            if hold_back:
                _hold_back_late_signals()
            return status
    except SystemExit as stop:  # argparse: --help (0) or a usage error (2)
        return stop.code if isinstance(stop.code, int) else 2
    except BrokenPipeError:  # stdout closed early ('flexcal ... | head'): the reader wanted no more
        with contextlib.suppress(OSError, ValueError, AttributeError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0
    except KeyboardInterrupt as interrupt:  # Ctrl-C, or SIGTERM (signals.Terminated)
        release_left(held_before)  # a lock whose block's release the signal got ahead of
        return _interrupted(command, interrupt, debug, written_folders()[n_written_before:])
    except Exception as error:  # noqa: BLE001 - the one place that turns errors into exit codes
        from .common import error_line, is_user_error
        from .signals import interrupt_behind

        interrupt = interrupt_behind(error)  # e.g. ImportError('initialization failed') from Ctrl-C
        if interrupt is not None:
            release_left(held_before)
            return _interrupted(command, interrupt, debug, written_folders()[n_written_before:])
        if debug:
            traceback.print_exc()
        print(error_line(command or "", error), file=sys.stderr)
        return 2 if is_user_error(error) else 1


def _interrupted(command: str | None, interrupt: KeyboardInterrupt, debug: bool, written=()) -> int:
    """One line for Ctrl-C / SIGTERM; the exit status 130 / 143. ``written``: the
    ``--out`` folders this run had already filled (the interrupt came after)."""
    from .signals import Terminated, exit_status

    if debug:
        traceback.print_exc()
    if written:
        kept = f" after the run wrote its results; the results in {written[-1]} are complete"
    elif command == "sweep":
        kept = "; finished designs are kept in --out and a rerun resumes"
    else:
        kept = "; nothing was written to --out"
    what = "terminated (SIGTERM)" if isinstance(interrupt, Terminated) else "interrupted"
    print(f"flexcal {command}: {what}{kept}", file=sys.stderr)
    return exit_status(interrupt)


def _hold_back_late_signals() -> None:
    """From here until the process has ended, Ctrl-C and SIGTERM are ignored: the run's
    status is decided and its results (if any) are complete, and the rest is the
    interpreter's shutdown (~0.5 s after a ``truth`` run, nearly all of it module teardown
    after Python has put SIGINT back to the system default, where no handler can print a
    line: a Ctrl-C there killed the process with no word). The process then ends with the
    run's own status. An ignored signal stays ignored through that teardown."""
    import signal
    import threading

    from .signals import HANDLED_SIGNALS

    if threading.current_thread() is threading.main_thread():
        for signum in HANDLED_SIGNALS:
            if signal.getsignal(signum) is not None:  # None: set outside Python, leave it
                signal.signal(signum, signal.SIG_IGN)


def _main(argv: list[str], command: str | None) -> int:
    from .common import (apply_config, check_file_options, configure_logging, effective_config, named_values,
                         print_config, summary_of)
    from ..output import dumps_strict

    parser = build_parser(only=command)
    if command is None:
        parser.parse_args(argv)  # --help exits here
        parser.print_help()
        return 2
    command_parser = parser._subparsers._group_actions[0].choices[command]
    module = importlib.import_module(f"flexcal.validation.cli.{COMMANDS[command][0]}")
    merged = apply_config(command_parser, module, argv[argv.index(command) + 1:])
    if merged is not None and "--print-config" in argv:
        print_config(command_parser, module, argv[argv.index(command) + 1:], merged, command)
        return 0
    args = parser.parse_args(argv)
    if merged is not None:
        args.config = effective_config(command_parser, args, merged)
    configure_logging(args.verbose, args.quiet)
    check_file_options(command_parser, args)  # a folder given where a file is expected: one line, now
    central_json = "json" in args._central and args.json
    with contextlib.ExitStack() as stack:
        if getattr(args, "out", None):
            from ..out_lock import reserved_out

            # before any computation: --out reserved for this run (a second run is refused), writable, not
            # another run's folder without --force, --force only on a run folder holding no input
            stack.enter_context(reserved_out(args.out, command=command, replace=getattr(args, "force", False),
                                             resume=getattr(module, "RESUMES_OUT", False),
                                             inputs=named_values(command_parser, args)))
        if central_json or args.quiet:
            devnull = stack.enter_context(open(os.devnull, "w"))
            stack.enter_context(contextlib.redirect_stdout(devnull))
        status = int(module.run(args) or 0)
    if central_json and status == 0 and args.out:
        print(dumps_strict(summary_of(args.out), sort_keys=True))
    return status

