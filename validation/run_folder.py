"""What makes a folder a flexcal run folder, and what ``--out`` and ``--force`` accept.

**The marker.** Every staged output (``output.staged_output``) carries a hidden file
``.flexcal-run`` holding the name of the command that wrote it. ``is_run_folder`` is true
for a folder with that marker, or with an earlier run's ``report.json`` and
``timings.json`` (runs written before the marker existed).

**The checks** (``out_folder``, before any computation; each failure one line): ``--out``
is not a file; it is writable (a file is actually made and removed: mode bits say nothing
for root or read-only mounts); it holds no visible file unless ``--force`` or the command
resumes its own run. ``--force`` replaces only a run folder, never one holding an input
of the command (``inputs_inside``: every value of the command line that names an existing
file or folder, and the paths a TOML input names), nor the home folder, the file-system
root or a folder holding the working directory. Who may write in ``--out`` while a run
goes on: ``flexcal.validation.out_lock``.
"""

from __future__ import annotations

import os
import tempfile
import tomllib
from pathlib import Path
from typing import Any, Iterable

__all__ = ["MARKER_NAME", "is_run_folder", "out_folder", "visible_entries", "inputs_inside", "referenced_paths"]

MARKER_NAME = ".flexcal-run"


def is_run_folder(folder: str | os.PathLike) -> bool:
    """Whether ``folder`` was written by a flexcal run: it holds the marker, or an earlier
    run's report.json and timings.json."""
    folder = Path(folder)
    return (folder / MARKER_NAME).is_file() or ((folder / "report.json").is_file()
                                                and (folder / "timings.json").is_file())


def referenced_paths(path: Path) -> list[Path]:
    """The existing files and folders that the string values of a TOML file name
    (relative to the file's folder or to the working directory): a scenario's trajectory
    file, a configuration's paths. Empty for anything that is not readable TOML."""
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    found: list[Path] = []

    def walk(value: Any) -> None:
        if isinstance(value, dict):
            for item in value.values():
                walk(item)
        elif isinstance(value, list):
            for item in value:
                walk(item)
        elif isinstance(value, str) and value and "\n" not in value and len(value) < 4096:
            for candidate in (path.parent / value, Path(value)):
                if os.path.lexists(candidate):
                    found.append(candidate)

    walk(table)
    return found


def _within(path: Path, folder: Path) -> bool:
    absolute = Path(os.path.abspath(path))
    return absolute.is_relative_to(folder) or absolute.resolve().is_relative_to(folder.resolve())


def inputs_inside(folder: str | os.PathLike, named: Iterable[tuple[str, Any]]) -> list[str]:
    """The inputs of a command that lie in ``folder`` (or are it), as 'OPTION PATH'.
    ``named``: (option, value) pairs of a parsed command line; every value (or list
    item) that is a string or path naming an existing file or folder counts, and so do
    the existing paths a TOML input names (``referenced_paths``). A measurement's JSON
    sidecar lies beside its CSV, so it is inside ``folder`` exactly when the CSV is."""
    folder = Path(os.path.abspath(folder))
    found = []
    for option, value in named:
        for item in value if isinstance(value, (list, tuple)) else (value,):
            if not isinstance(item, (str, os.PathLike)) or not str(item) or not os.path.lexists(item):
                continue
            path = Path(item)
            candidates = [path] + (referenced_paths(path) if path.suffix == ".toml" and path.is_file() else [])
            for candidate in candidates:
                if _within(candidate, folder):
                    found.append(f"{option} {item}" + ("" if candidate is path else f" (names {candidate})"))
    return found


def _probe_writable(folder: Path, what: str) -> None:
    """ValueError (one line) unless a file can be made in ``folder`` (tried, not guessed
    from mode bits: root ignores those, read-only mounts do not show in them)."""
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".flexcal-probe.", dir=folder))
    except OSError as error:
        raise ValueError(f"--out {what}: cannot write in {folder} ({error.strerror or error}); "
                         f"choose a folder you can write to") from None


def visible_entries(folder: Path) -> list[str]:
    """The names in ``folder`` not starting with '.' (a run's files; not the marker, lock or staging)."""
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))


def _shown(names: list[str]) -> str:
    return ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")


def out_folder(out_dir: str | os.PathLike, *, replace: bool = False, resume: bool = False,
               inputs: Iterable[tuple[str, Any]] = ()) -> Path:
    """``--out`` as a path, checked before any computation: not a file, writable (the
    folder itself if it exists, else its nearest existing parent), and, unless
    ``replace`` (``--force``) or ``resume`` (commands that continue an earlier run in
    the same folder), not already holding files (another run's report, stale PNGs).
    ``replace`` empties only a run folder (``run_folder.is_run_folder``) that holds none
    of ``inputs`` ((option, value) pairs of the command line: ``run_folder.inputs_inside``).
    ValueError with one line saying what to do."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a folder; give a folder name")
    if out.is_dir():
        _probe_writable(out, str(out))
        resolved = out.resolve()
        if replace and (resolved == Path.home().resolve() or resolved == Path(resolved.anchor)
                        or Path.cwd().resolve().is_relative_to(resolved)):
            raise ValueError(f"--out {out} with --force would empty {resolved} (the home folder, the file-system root "
                             f"or a folder holding the working directory); give a folder of its own")
        held = visible_entries(out)
        if held and not (replace or resume):
            raise ValueError(f"--out {out} already holds files ({_shown(held)}); pass --force to replace them "
                             f"or choose another folder")
        if held and replace:
            inside = inputs_inside(out, inputs)
            if inside:
                raise ValueError(f"--out {out} holds an input of this command ({'; '.join(inside)}); --force would "
                                 f"delete it: choose another --out")
            if not is_run_folder(out):
                raise ValueError(f"--out {out} is not a flexcal run folder (no {MARKER_NAME} marker, no report.json "
                                 f"with timings.json) and holds {_shown(held)}; --force replaces only an earlier "
                                 f"run's folder: choose a new or empty folder")
        return out
    ancestor = out.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ValueError(f"--out {out}: {ancestor} is a file, not a folder; choose another --out")
    _probe_writable(ancestor, str(out))
    return out
