"""Writing results whole or not at all.

``staged_output(out_dir)`` yields a temporary folder beside ``out_dir``; when the
``with`` block finishes without error its files are moved into ``out_dir`` (created if
needed, existing files of the same name replaced); on any error, ``KeyboardInterrupt``
(Ctrl-C) included, the temporary folder is removed and ``out_dir`` is untouched. A
fresh ``out_dir`` appears in one rename; into an existing one each file moves by its own
rename (each file is whole, old or new), with Ctrl-C held back until the moves are done.

``atomic_path(path)`` yields a temporary name beside ``path`` for any writer (matplotlib,
numpy, csv); on success it is renamed onto ``path``, on error deleted. ``write_json`` and
``write_text`` use it.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import tempfile
import threading
import uuid
from pathlib import Path
from typing import Any, Iterator

import numpy as np

__all__ = ["out_folder", "staged_output", "atomic_path", "write_json", "write_text", "to_jsonable", "interrupts_deferred"]

_UMASK = os.umask(0o022)  # read the process umask (only settable, not readable) ...
os.umask(_UMASK)  # ... and put it back: folders made by mkdtemp get the usual permissions


@contextlib.contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Hold back Ctrl-C (SIGINT) inside the block and raise it right after; a no-op off
    the main thread (where Python never delivers signals anyway)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[tuple[int, Any]] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append((signum, frame)))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        if callable(previous):
            previous(*received[0])
        else:
            raise KeyboardInterrupt


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path in ``path``'s folder (same suffix, so writers that pick the format
    from it still work); renamed onto ``path`` when the block succeeds, removed otherwise."""
    path = Path(path)
    # a fresh name (not created here: the writer creates it with the usual permissions)
    tmp_path = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:12]}.tmp{path.suffix}")
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def out_folder(out_dir: str | os.PathLike) -> Path:
    """``--out`` as a path; ValueError if it exists and is not a folder."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a folder; give a folder name")
    return out


@contextlib.contextmanager
def staged_output(out_dir: str | os.PathLike) -> Iterator[Path]:
    out = out_folder(out_dir)
    parent = out.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=parent))
    os.chmod(staging, 0o777 & ~_UMASK)
    try:
        yield staging
        with interrupts_deferred():
            try:
                os.rename(staging, out)  # a new (or empty) folder: one atomic step
            except OSError:
                out.mkdir(parents=True, exist_ok=True)
                for item in staging.iterdir():
                    target = out / item.name
                    if target.is_dir() and not target.is_symlink():
                        shutil.rmtree(target)
                    os.replace(item, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def to_jsonable(value: Any) -> Any:
    """numpy arrays and scalars -> lists and floats, recursively."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


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
    """Write ``data`` as indented JSON (atomically: temporary file, then rename)."""
    write_text(path, json.dumps(to_jsonable(data), indent=2) + "\n", fsync=fsync)
