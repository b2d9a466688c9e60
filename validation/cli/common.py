"""What every ``flexcal`` sub-command shares: options, configuration files, errors, progress.

``cli.py`` calls ``install_common_options(parser, module)`` after the module's
``configure(parser)``; a command module gets, without writing any of it:

- ``-v/--verbose`` (repeatable: logging INFO, DEBUG), ``-q/--quiet`` (no progress, no
  text on stdout), ``--debug`` (print the traceback of an error);
- ``--json`` if it has ``--out``: stdout is then only the JSON summary of
  ``DIR/report.json`` (``summary_of``);
- ``--config FILE`` and ``--print-config`` if it defines ``DEFAULT_CONFIG`` (a dict of
  TOML values): keys that are option destinations (``sobol_n`` for ``--sobol-n``) set
  that option's default, so the precedence is command line > file > DEFAULT_CONFIG;
  the effective configuration is ``args.config``;
- an epilog listing its ``EXAMPLES`` (tuple of command lines).

A flag the module already defined is left to the module (``forward --json`` prints its
own JSON). ``named_values`` lists every parsed value by option (what ``--force`` checks for
the command's inputs), ``check_file_options`` refuses a folder given for a file. ``add_out``, ``add_seed`` and ``add_scenario`` give the shared options one
name and one help text everywhere (``options.py``).
"""

from __future__ import annotations

import argparse
import errno
import json
import logging
import os
import re
import sys
from pathlib import Path
from typing import Any, Iterable

__all__ = ["install_common_options", "apply_config", "print_config", "summary_of", "show_progress", "error_line",
           "is_user_error", "configure_logging", "without_timings", "examples_epilog", "named_values",
           "check_file_options"]

# Exceptions that mean "the input cannot be used" (one line, exit 2), beside ValueError
# and OSError; matched by class name so the check imports no solver module.
USER_ERROR_NAMES = frozenset({"ConvergenceError", "NonConvergenceError", "InvertedElementsError",
                              "BudgetExhausted", "NotInvertibleError", "TOMLDecodeError"})


def examples_epilog(module) -> str | None:
    """'examples:' followed by the module's EXAMPLES (or the docstring's indented
    'flexcal ...' lines), and a pointer to the common options."""
    examples = list(getattr(module, "EXAMPLES", ()) or ())
    if not examples:
        examples = [line.strip() for line in (module.__doc__ or "").splitlines() if line.startswith("    flexcal ")]
    lines = ["examples:", *(f"  {e}" for e in examples)] if examples else []
    lines += ["", "common options (every command): -v/-q, --debug; --json with --out; --config FILE and "
                  "--print-config where the command has a configuration (docs/cli.md)."]
    return "\n".join(lines)


def _add_if_free(parser: argparse.ArgumentParser, flags: Iterable[str], **kwargs) -> bool:
    free = [f for f in flags if f not in parser._option_string_actions]
    if free and (kwargs.get("dest") or any(f.startswith("--") for f in free)):
        parser.add_argument(*free, **kwargs)
        return True
    return False


def install_common_options(parser: argparse.ArgumentParser, module) -> None:
    """Add the shared options to a configured sub-command parser (see the module doc)."""
    group = parser.add_argument_group("common options")
    _add_if_free(group, ["-v", "--verbose"], dest="verbose", action="count", default=0,
                 help="more log output (-vv: debug)")
    _add_if_free(group, ["-q", "--quiet"], dest="quiet", action="store_true",
                 help="no progress bars and no text on stdout (errors still go to stderr)")
    _add_if_free(group, ["--debug"], dest="debug", action="store_true",
                 help="on an error, print the Python traceback as well as the one-line message")
    central = set()
    if "--out" in parser._option_string_actions and "--json" not in parser._option_string_actions:
        group.add_argument("--json", action="store_true",
                           help="print only a JSON summary of DIR/report.json on stdout")
        central.add("json")
    if "--out" in parser._option_string_actions and not getattr(module, "RESUMES_OUT", False):
        _add_if_free(group, ["--force"], dest="force", action="store_true",
                     help="--out may hold an earlier run: its files are replaced (removed when the new "
                          "results move in); without it such a folder is refused")
    defaults = getattr(module, "DEFAULT_CONFIG", None)
    if defaults is not None:
        from ..config import check_default_config

        check_default_config(defaults, f"{module.__name__}.DEFAULT_CONFIG")
        group.add_argument("--config", dest="config_path", metavar="FILE",
                           help="TOML file of settings (keys and defaults: --print-config); "
                                "command-line options override it")
        group.add_argument("--print-config", action="store_true",
                           help="print the effective configuration as TOML and exit")
        _set_option_defaults(parser, defaults)
    parser.set_defaults(_central=frozenset(central), config=dict(defaults or {}))
    for attr, value in (("verbose", 0), ("quiet", False), ("debug", False), ("force", False)):
        if attr not in {a.dest for a in parser._actions}:
            parser.set_defaults(**{attr: value})


def _option_dests(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {a.dest: a for a in parser._actions if a.option_strings}


def _set_option_defaults(parser: argparse.ArgumentParser, values: dict[str, Any]) -> None:
    actions = _option_dests(parser)
    found = {}
    for key, value in values.items():
        action = actions.get(key)
        if action is None:
            continue
        if action.choices is not None and value not in action.choices:
            raise ValueError(f"{key} = {value!r} must be one of {', '.join(map(str, action.choices))}")
        found[key] = value
    parser.set_defaults(**found)


def _option_value(argv: list[str], flag: str) -> str | None:
    for k, arg in enumerate(argv):
        if arg == flag and k + 1 < len(argv):
            return argv[k + 1]
        if arg.startswith(flag + "="):
            return arg.split("=", 1)[1]
    return None


def apply_config(parser: argparse.ArgumentParser, module, argv: list[str]) -> dict[str, Any] | None:
    """Read ``--config FILE`` from ``argv`` (before the full parse) and make its values
    the parser's defaults; the merged configuration, or None without DEFAULT_CONFIG."""
    defaults = getattr(module, "DEFAULT_CONFIG", None)
    if defaults is None:
        return None
    path = _option_value(argv, "--config")
    if path is None:
        return dict(defaults)
    from ..config import read_config_file

    merged = read_config_file(path, defaults)
    try:
        _set_option_defaults(parser, merged)
    except ValueError as error:  # a value of the right type that is not one of the option's choices
        raise ValueError(f"--config {path}: {error}") from None
    parser.set_defaults(config=merged)
    return merged


def effective_config(parser: argparse.ArgumentParser, args: argparse.Namespace, merged: dict[str, Any]) -> dict:
    """``merged`` with the keys that are options replaced by their parsed values."""
    actions = _option_dests(parser)
    out = dict(merged)
    for key in merged:
        if key in actions and getattr(args, key, None) is not None:
            value = getattr(args, key)
            out[key] = float(value) if isinstance(merged[key], float) and not isinstance(value, bool) else value
    return out


def print_config(parser: argparse.ArgumentParser, module, argv: list[str], merged: dict[str, Any], command: str) -> None:
    """Parse ``argv`` with nothing required and print the effective configuration."""
    from ..config import format_config

    for action in parser._actions:
        action.required = False
    for group in parser._mutually_exclusive_groups:
        group.required = False
    args = parser.parse_args(argv)
    header = (f"flexcal {command}: effective configuration (defaults < --config file < command line).\n"
              f"Save it, edit it, run 'flexcal {command} --config FILE ...'.")
    print(format_config(effective_config(parser, args, merged), header=header), end="")


def _scalars(table: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in table.items() if isinstance(v, (str, int, float, bool)) or v is None}


def summary_of(out_dir: str | Path) -> dict[str, Any]:
    """The JSON summary of a run folder: report.json's ``summary`` table if it has one,
    else its top-level numbers, strings and booleans, with the matching times of
    timings.json (``wall_s``); plus ``out`` and ``files``."""
    out = Path(out_dir)
    report_path, timings_path = out / "report.json", out / "timings.json"
    summary: dict[str, Any] = {}
    if report_path.is_file():
        report = json.loads(report_path.read_text())
        timings = json.loads(timings_path.read_text()) if timings_path.is_file() else {}
        if isinstance(report.get("summary"), dict):
            summary = {**report["summary"], **_scalars(timings.get("summary") or {})}
        else:
            summary = {**_scalars(report), **_scalars(timings)}
    summary["out"] = str(out)
    summary["files"] = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    return summary


def without_timings(value: Any) -> Any:
    """A report with every ``TIMING_KEYS`` entry removed, recursively (what
    ``output.write_report`` puts in report.json; the keys: ``output.TIMING_KEYS``)."""
    from ..output import split_timings

    return split_timings(value)[0]


def show_progress(args: argparse.Namespace) -> bool:
    """Progress output wanted: not ``-q`` (bars also hide themselves off a terminal)."""
    return not getattr(args, "quiet", False)


def is_user_error(error: BaseException) -> bool:
    """Whether ``error`` is about the input (bad file, value, geometry, no convergence)
    rather than a bug in flexcal."""
    if isinstance(error, (RecursionError, NotImplementedError)):
        return False
    if isinstance(error, (ValueError, OSError, RuntimeError)):
        return True
    return any(cls.__name__ in USER_ERROR_NAMES for cls in type(error).__mro__)


def error_line(command: str, error: BaseException) -> str:
    """One line: 'flexcal <command>: error: <message>' (newlines folded)."""
    message = " ".join(str(error).split()) or type(error).__name__
    if not is_user_error(error):
        return (f"flexcal {command}: internal error: {type(error).__name__}: {message} "
                f"(rerun with --debug for the traceback and report it)")
    if isinstance(error, OSError) and not isinstance(error, FileNotFoundError) and error.filename:
        message = f"{error.strerror or message}: {error.filename}"
    if isinstance(error, OSError) and error.errno in _DISK_FULL:
        if not error.filename:  # no path known (a writer outside --out): say where flexcal writes
            message = f"{error.strerror or message} (free space in --out, the FEM cache or the temporary folder)"
        else:
            message += " (free space there, or choose another --out)"
    return f"flexcal {command}: error: {message}"


_DISK_FULL = frozenset({errno.ENOSPC, errno.EDQUOT})


def named_values(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list[tuple[str, Any]]:
    """(option, value) of every argument of the command line but ``--out`` (the option's
    longest flag, or a positional's name): what ``run_folder.inputs_inside`` looks through
    for the command's inputs, so a new option naming a file is covered without a list."""
    pairs = []
    for action in parser._actions:
        if action.dest in ("out", "help", argparse.SUPPRESS) or not hasattr(args, action.dest):
            continue
        label = max(action.option_strings, key=len) if action.option_strings else action.metavar or action.dest
        pairs.append((str(label), getattr(args, action.dest)))
    return pairs


# the metavars of options that name an existing or a new file (one '|' alternative is enough)
_FILE_METAVAR = re.compile(r"^(FILE|CSV|REPORT|TOML|JSON|.*\.(csv|json|toml))$")


def check_file_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """ValueError (one line) if an option whose metavar names a file (``FILE``, ``CSV``,
    ``REPORT``, ``DATA.csv``, ...) was given a folder. ``NAME|FILE`` values count only
    when they look like a path (a built-in name wins over a folder of that name)."""
    for action in parser._actions:
        if not isinstance(action.metavar, str):
            continue
        parts = action.metavar.split("|")
        if not any(_FILE_METAVAR.match(part) for part in parts):
            continue
        value = getattr(args, action.dest, None)
        if not isinstance(value, (str, os.PathLike)) or not os.path.isdir(value):
            continue
        if len(parts) > 1 and os.sep not in str(value) and not str(value).startswith("."):
            continue
        label = max(action.option_strings, key=len) if action.option_strings else action.metavar
        held = sorted(p.name for p in Path(value).iterdir() if p.is_file() and not p.name.startswith("."))[:3]
        inside = f" (it holds {', '.join(held)})" if held else ""
        raise ValueError(f"{label} {value} is a folder, not a file; give the path of a file{inside}")


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is at the time (tests swap it)."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):
        pass


def configure_logging(verbose: int, quiet: bool) -> None:
    """Level of the ``flexcal`` loggers (-q: errors, default: warnings, -v: info, -vv:
    debug), one stderr handler; the root logger is left alone."""
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    logger = logging.getLogger("flexcal")
    logger.setLevel(level)
    if not any(getattr(h, "_flexcal", False) for h in logger.handlers):
        handler = _StderrHandler()
        handler._flexcal = True
        handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
        logger.addHandler(handler)
