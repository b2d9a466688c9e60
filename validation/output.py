"""Writing results whole or not at all.

``out_folder(out_dir)`` checks ``--out`` before any computation: not a file, writable,
and not holding the files of another run unless ``--force`` (``replace=True``) or the
command resumes its own earlier run (``resume=True``: ``sweep``, ``diagnose-benchmark``).
``--force`` replaces only a run folder (the hidden marker ``.flexcal-run``, or an earlier
run's report.json with timings.json) that holds none of the command's inputs (``inputs``:
``run_folder.inputs_inside``); anything else is refused in one line. The command line
calls it through ``run_folder.reserved_out``, which first reserves ``--out`` for the run
(an owner-tagged lock file: a second run to the same folder is refused; a killed run's
lock is cleared; see ``flexcal.validation.run_folder``).

``staged_output(out_dir)`` yields a temporary staging folder (hidden, ``.NAME.*``)
beside a new ``out_dir``, or inside an existing one, so it is always on the target's own
file system (a mount point as ``--out`` works; a move that still crosses file systems is
copied to a temporary name and renamed). The folder's name records its owner (a hash of
the host name, the process id and, on Linux, the process's start time:
``.NAME.flexcal-HOST-PID-START.XXXXXXXX``), so a run killed where it cannot clean up
(SIGKILL, the OOM killer, a power cut) leaves a folder the next run can recognise:
``staged_output`` first removes every such folder in the place it stages in whose owner,
on this host, is gone (``remove_stale_staging``); a live process's folder, another host's
and folders of other names are never touched. When the ``with`` block finishes without error
its files are moved into ``out_dir``; with ``replace`` whatever ``out_dir`` held before is
removed at that moment (a failed run keeps the old results). On any error,
``KeyboardInterrupt`` (Ctrl-C) and ``signals.Terminated`` (SIGTERM) included, the staging
folder is removed and ``out_dir`` is untouched; so too when such an interrupt was received
and swallowed on the way (raised in a destructor, ``interrupts.raise_received``). A fresh ``out_dir`` appears in one
rename; into an existing one each file moves by its own rename (each file is whole, old
or new), with Ctrl-C and SIGTERM held back until the moves are done. The staged files
include the marker ``.flexcal-run`` (the command's name); ``replace`` removes only
visible files, so the marker and the lock stay. ``staged_output`` holds ``out_dir``'s
reservation for its block (re-entrant: inside the command line's own it adds nothing).
An ``OSError`` of the block or the moves that names no file (a writer's ENOSPC or EFBIG)
is raised again naming ``out_dir``, and one naming a file in the staging folder names the
same file in ``out_dir``; ``atomic_path`` names its target likewise.

``atomic_path(path)`` (``flexcal.geometry.atomic``, the project's one write-to-temp-then-rename,
re-exported here) yields a temporary name beside ``path`` for any writer (matplotlib, numpy,
csv); on success it is renamed onto ``path``, on error deleted. ``write_json``, ``write_text``
and the cross-file-system copy of the moves use it.

``write_report(folder, report)`` is how every command writes its report: ``report.json``
holds the results only, the same bytes for the same input; the wall-clock and CPU seconds
(the ``TIMING_KEYS`` anywhere in the report) go to ``timings.json``, the one file of a run
folder that differs from run to run (docs/cli.md, "Byte-identical reports").
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import math
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from flexcal.fem.owners import OWNER_TAG, owner_tag, remove_folders_of_gone_owners
from flexcal.geometry.atomic import atomic_path

from .interrupts import interrupts_deferred, raise_received
from .run_folder import MARKER_NAME, out_folder, visible_entries

__all__ = ["out_folder", "staged_output", "atomic_path", "write_json", "write_text", "to_jsonable", "dumps_strict",
           "interrupts_deferred", "TIMING_KEYS", "split_timings", "write_report", "remove_stale_staging",
           "written_folders"]

# Report keys that hold wall-clock or CPU times [s]: they differ between two runs of the
# same input, so ``write_report`` moves them from report.json to timings.json.
TIMING_KEYS = frozenset({"wall_s", "timings_s", "elapsed_s"})

_UMASK = os.umask(0o022)  # read the process umask (only settable, not readable) ...
os.umask(_UMASK)  # ... and put it back: folders made by mkdtemp get the usual permissions


def _move(source: Path, target: Path) -> None:
    """``os.replace(source, target)``; across file systems (EXDEV) a copy to a temporary
    name beside ``target``, renamed onto it, then the source removed."""
    try:
        os.replace(source, target)
        return
    except OSError as error:
        if error.errno != errno.EXDEV:
            raise
    with atomic_path(target, suffix=".partial") as partial:
        if source.is_dir() and not source.is_symlink():
            shutil.copytree(source, partial, symlinks=True)
        else:
            shutil.copy2(source, partial, follow_symlinks=False)
    if source.is_dir() and not source.is_symlink():
        shutil.rmtree(source)
    else:
        source.unlink()


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()


# .NAME.flexcal-HOST-PID-START.XXXXXXXX (mkdtemp's 8 random characters; owners.owner_tag)
_STAGING_NAME = re.compile(rf"^\..*\.flexcal-{OWNER_TAG}\.[A-Za-z0-9_]{{8}}$")


def remove_stale_staging(folder: str | os.PathLike) -> list[str]:
    """Remove the staging folders in ``folder`` left by runs of this host whose process is
    gone (killed by SIGKILL, out of memory, ...); returns their names. Folders of live
    processes, of other hosts and of any other name stay; errors are ignored (a folder
    that cannot be removed stays as it was)."""
    removed = remove_folders_of_gone_owners(folder, _STAGING_NAME)
    if removed:
        logging.getLogger("flexcal.output").info("removed staging folders of killed runs: %s", ", ".join(removed))
    return removed


_written: list[Path] = []  # the --out folders staged_output filled in this process (resolved)


def written_folders() -> tuple[Path, ...]:
    """The ``--out`` folders (resolved) whose results ``staged_output`` moved in during
    this process, oldest first: a Ctrl-C after that point must not say nothing was written."""
    return tuple(_written)


def _naming_the_path(error: OSError, staging: Path, out: Path) -> OSError:
    """``error`` naming where it happened as the user knows it: a path inside the staging
    folder as the same path in ``out``; no path at all (a writer's ENOSPC, EFBIG, EIO) as
    ``out``."""
    if error.errno is None:
        return error
    name = error.filename
    if name is None:
        name = str(out)
    elif Path(name).is_relative_to(staging):
        name = str(out / Path(name).relative_to(staging))
    else:
        return error
    return type(error)(error.errno, error.strerror, name)


@contextlib.contextmanager
def staged_output(out_dir: str | os.PathLike, *, replace: bool = False, resume: bool = False) -> Iterator[Path]:
    """A staging folder for the outputs of a run, moved into ``out_dir`` when the block
    succeeds, removed otherwise (see the module doc). ``replace`` (``--force``): what
    ``out_dir`` held before is removed when the new files move in (not before: a failed
    run keeps the old results); ``resume``: files of the folder not written now stay.
    Checks ``out_dir`` first (``out_folder``) and holds its reservation for the block
    (``run_folder.reserved``: re-entrant, so inside the command line's own it adds
    nothing); writes the marker ``.flexcal-run`` (the command's name) with the files."""
    from .out_lock import held_command, reserved

    out = out_folder(out_dir, replace=replace, resume=resume)
    command = held_command(out) or "python"
    with reserved(out, command=command):
        if out.is_dir():  # stage inside it: same file system (a mount point as --out), no EXDEV
            where = out
        else:
            where = out.absolute().parent
            where.mkdir(parents=True, exist_ok=True)
        remove_stale_staging(where)
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name or 'out'}.flexcal-{owner_tag()}.", dir=where))
        os.chmod(staging, 0o777 & ~_UMASK)
        try:
            yield staging
            raise_received()  # an interrupt a library swallowed (interrupts' module doc): nothing moves in
            (staging / MARKER_NAME).write_text(f"{command}\n", encoding="utf-8")
            with interrupts_deferred():
                _move_in(staging, out, replace)
                _written.append(out.resolve())
        except OSError as error:
            raised = _naming_the_path(error, staging, out)
            if raised is error:
                raise
            raise raised from error
        finally:
            shutil.rmtree(staging, ignore_errors=True)


def _move_in(staging: Path, out: Path, replace: bool) -> None:
    """The staged files into ``out`` (see the module doc); ``replace`` first removes its
    visible files (the hidden lock and marker stay)."""
    if not out.is_dir():
        try:
            os.rename(staging, out)  # a new folder: one atomic step
            return
        except OSError:
            out.mkdir(parents=True, exist_ok=True)
    if replace:
        for name in visible_entries(out):
            _remove(out / name)
    for item in staging.iterdir():
        target = out / item.name
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target)
        _move(item, target)


# Strict JSON (RFC 8259 has no NaN or Infinity): a non-finite number is written as null,
# and the object holding it gets "<key>_note" saying what it was (docs/cli.md).
_NONFINITE_REASONS = {"condition_number": "infinite: rank deficient (the data cannot separate some parameters)",
                      "condition_number_subset": "infinite: rank deficient (the data cannot separate some parameters)"}


def _nonfinite_name(value: float) -> str:
    return "NaN (not a number)" if math.isnan(value) else ("+infinity" if value > 0 else "-infinity")


def _count_nonfinite(value: Any) -> int:
    if isinstance(value, float):
        return 0 if math.isfinite(value) else 1
    if isinstance(value, list):
        return sum(_count_nonfinite(v) for v in value)
    return 0


def to_jsonable(value: Any) -> Any:
    """numpy arrays and scalars -> lists and floats, recursively; non-finite floats ->
    None, with a ``<key>_note`` beside them in the enclosing object (strict JSON)."""
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        notes: dict[str, str] = {}
        for key, item in value.items():
            key, item = str(key), to_jsonable(item)
            if isinstance(item, float) and not math.isfinite(item):
                notes[f"{key}_note"] = _NONFINITE_REASONS.get(key, _nonfinite_name(item)) + "; written as null"
                item = None
            elif isinstance(item, list) and (n_bad := _count_nonfinite(item)):
                notes[f"{key}_note"] = f"{n_bad} non-finite entries (NaN or infinity) written as null"
                item = _nulled(item)
            out[key] = item
        for key, note in notes.items():
            out.setdefault(key, note)
        return out
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    return value


def _nulled(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, list):
        return [_nulled(v) for v in value]
    return value


def dumps_strict(data: Any, **kwargs: Any) -> str:
    """``json.dumps`` of ``to_jsonable(data)`` that never writes NaN or Infinity."""
    return json.dumps(_nulled(to_jsonable(data)), allow_nan=False, **kwargs)


def write_text(path: str | os.PathLike, text: str, *, fsync: bool = False) -> None:
    """Write ``text`` to ``path`` atomically (temporary file, then rename); ``fsync``
    flushes it to disk first (for records that must survive a crash)."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as stream:
            stream.write(text)
            if fsync:
                stream.flush()
                os.fsync(stream.fileno())


def write_json(path: str | os.PathLike, data: Any, *, fsync: bool = False) -> None:
    """Write ``data`` as indented strict JSON (non-finite numbers as null with a note;
    atomically: temporary file, then rename)."""
    write_text(path, dumps_strict(data, indent=2) + "\n", fsync=fsync)


def split_timings(value: Any) -> tuple[Any, Any]:
    """(``value`` without its ``TIMING_KEYS`` entries, those entries in the same nesting),
    recursively through dicts and lists. The second is None where ``value`` holds no
    timing; a list with timings in some entries keeps one entry per item (``{}`` for an
    item without), so ``rows[k]``'s time is ``timings["rows"][k]``."""
    if isinstance(value, dict):
        results: dict[str, Any] = {}
        timings: dict[str, Any] = {}
        for key, item in value.items():
            if key in TIMING_KEYS:
                timings[key] = item
                continue
            results[key], inner = split_timings(item)
            if inner is not None:
                timings[key] = inner
        return results, (timings or None)
    if isinstance(value, (list, tuple)):
        pairs = [split_timings(item) for item in value]
        results_list = [r for r, _ in pairs]
        if all(t is None for _, t in pairs):
            return results_list, None
        return results_list, [{} if t is None else t for _, t in pairs]
    return value, None


def write_report(folder: str | os.PathLike, report: dict[str, Any]) -> dict[str, Any]:
    """``folder/report.json``: ``report`` without its timing keys (strict JSON, atomic);
    ``folder/timings.json``: those keys [s] in the same nesting, when it has any. Returns
    what report.json holds."""
    folder = Path(folder)
    results, timings = split_timings(report)
    write_json(folder / "report.json", results)
    if timings is not None:
        write_json(folder / "timings.json", timings)
    return results
