"""``--out`` reserved for one run at a time.

``reserved(out_dir, command=...)`` takes an exclusive lock on ``--out`` for as long as
its block runs: a file made with an exclusive create (a temporary file hard-linked onto
the name, so the lock never exists without its owner; ``O_CREAT|O_EXCL`` where the file
system has no hard links), ``DIR/.flexcal-lock`` inside an existing folder,
``.NAME.flexcal-lock`` beside a folder that does not exist yet (both places are checked,
so a run that finds the folder made by a live run in between is refused as well). The
lock holds its owner's tag (``fem/owners.owner_tag``: host, process id, start time), the
command and the time it was taken. A second run to the same folder is refused
(``OutInUse``, a ValueError: one line, exit 2) before it computes; a lock whose owner, on
this host, is gone (SIGKILL, the OOM killer, a power cut) is cleared (renamed aside, then
checked to be the one read, so two runs clearing it at once cannot both win). A lock of
another host is never cleared (its process ids mean nothing here): the message names the
file to remove. The reservation is re-entrant in one process (the command line holds it
for the whole command, ``reserved_out``; ``output.staged_output`` inside it reuses it) and
is released when the block ends, whatever ends it (success, error, Ctrl-C, SIGTERM); a
Ctrl-C or SIGTERM that arrives while the lock is being taken or released is held back until
that is done (``interrupts.interrupts_deferred``), then delivered.
``sweep`` and ``diagnose-benchmark`` resume their own earlier run once it has released
the folder. Replacing a folder (``--force``) removes only its visible files: the lock
and the marker (``run_folder``) are hidden and stay.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Iterator

from flexcal.fem.owners import OWNER_TAG, host_hash, owner_alive, owner_tag

from .interrupts import interrupts_deferred

__all__ = ["LOCK_NAME", "OutInUse", "Holder", "lock_paths", "read_holder", "reserved", "reserved_out", "held_command",
           "held_folders", "release_left"]

LOCK_NAME = ".flexcal-lock"
# a lock with no readable owner is taken to be one being written (O_EXCL fallback) for
# this long [s], then to be left by a run killed between its create and its write
_UNREADABLE_GRACE_S = 10.0


class OutInUse(ValueError):
    """``--out`` is reserved by another run (one line, exit 2)."""


@dataclass(frozen=True, kw_only=True)
class Holder:
    """The owner recorded in a lock file: ``host`` (8 hex digits, ``owners.host_hash``),
    ``pid``, ``start`` (clock ticks after boot, 0 unknown), ``command``, ``since`` [s
    since the epoch]."""

    host: str
    pid: int
    start: int
    command: str
    since: float

    @property
    def alive(self) -> bool:
        """In doubt (another host), alive."""
        return self.host != host_hash() or owner_alive(self.pid, self.start)

    def describe(self) -> str:
        where = "on this host" if self.host == host_hash() else f"on another host ({self.host})"
        since = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(self.since))
        return f"flexcal {self.command}, pid {self.pid} {where}, since {since}"


def lock_paths(out_dir: str | os.PathLike) -> tuple[Path, Path]:
    """(inside, beside): the lock file inside ``out_dir`` and the one beside it."""
    out = Path(out_dir).resolve()
    return out / LOCK_NAME, out.parent / f".{out.name}.flexcal-lock"


def _lock_text(command: str) -> str:
    return json.dumps({"owner": owner_tag(), "command": command, "since": round(time.time(), 3)}) + "\n"


def read_holder(lock: Path) -> Holder | None | str:
    """The owner recorded in ``lock``; None if there is no such file; the text if it
    names no owner (being written, or not flexcal's)."""
    try:
        text = lock.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return None
    except OSError as error:
        return f"unreadable ({error.strerror or error})"
    try:
        data = json.loads(text)
        host, pid, start = re.fullmatch(OWNER_TAG, data["owner"]).groups()
        return Holder(host=host, pid=int(pid), start=int(start), command=str(data.get("command", "?")),
                      since=float(data.get("since", 0.0)))
    except (ValueError, KeyError, TypeError, AttributeError):
        return text


def _create(lock: Path, text: str) -> None:
    """Make ``lock`` holding ``text`` if it does not exist (FileExistsError if it does)."""
    tmp = lock.with_name(f"{lock.name}.{uuid.uuid4().hex[:12]}.tmp")
    tmp.write_text(text, encoding="utf-8")
    try:
        os.link(tmp, lock)  # atomic, and the lock appears with its owner already in it
        return
    except FileExistsError:
        raise
    except OSError as error:  # no hard links on this file system: exclusive create, then write
        if error.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
            raise
    finally:
        tmp.unlink(missing_ok=True)
    handle = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    with os.fdopen(handle, "w", encoding="utf-8") as stream:
        stream.write(text)


def _clear_stale(lock: Path, text_read: str) -> bool:
    """Remove ``lock`` if it still holds ``text_read`` (a gone owner's); False if another
    run replaced it meanwhile (it is then put back)."""
    aside = lock.with_name(f"{lock.name}.{uuid.uuid4().hex[:12]}.stale")
    try:
        os.rename(lock, aside)
    except FileNotFoundError:
        return True  # another run cleared it first
    try:
        if aside.read_text(encoding="utf-8", errors="replace") == text_read:
            return True
        with contextlib.suppress(FileExistsError):
            os.link(aside, lock)  # a live run's lock, taken between our read and our rename: put it back
        return False
    finally:
        aside.unlink(missing_ok=True)


def _refusal(out: str, lock: Path, holder: Holder | str) -> OutInUse:
    if isinstance(holder, Holder):
        if holder.host != host_hash():
            return OutInUse(f"--out {out} is in use by {holder.describe()}; wait for it to end, or remove {lock} "
                            f"if no flexcal run uses the folder any more")
        return OutInUse(f"--out {out} is in use by {holder.describe()}; wait for it to end or choose another "
                        f"folder")
    return OutInUse(f"--out {out} is locked by {lock}, which names no flexcal run; remove it if no run uses the "
                    f"folder, or choose another folder")


def _take(out: str, lock: Path, text: str) -> None:
    """Create ``lock`` holding ``text``, clearing a gone owner's lock first; OutInUse
    if a live run holds it."""
    for _ in range(5):
        try:
            _create(lock, text)
            return
        except FileExistsError:
            pass
        try:
            raw = lock.read_text(encoding="utf-8", errors="replace")
        except FileNotFoundError:
            continue  # released meanwhile: try again
        holder = read_holder(lock)
        if holder is None:
            continue
        if isinstance(holder, Holder):
            stale = not holder.alive or (holder.pid == os.getpid() and holder.host == host_hash())
        else:  # no owner in it: one being written right now, or one left by a run killed at that moment
            try:
                stale = time.time() - lock.stat().st_mtime > _UNREADABLE_GRACE_S
            except FileNotFoundError:
                continue
        if not stale or not _clear_stale(lock, raw):
            raise _refusal(out, lock, read_holder(lock) or holder)
    raise _refusal(out, lock, read_holder(lock) or "?")


def _release(lock: Path, text: str) -> None:
    """Remove ``lock`` if it is still ours."""
    with contextlib.suppress(OSError):
        if lock.read_text(encoding="utf-8") == text:
            lock.unlink()


@dataclass
class _Reservation:
    lock: Path
    text: str
    command: str
    made: list[Path]  # parent folders made for the lock, removed on release if still empty
    count: int = 1


_held: dict[Path, _Reservation] = {}
_held_guard = threading.Lock()


def held_command(out_dir: str | os.PathLike) -> str | None:
    """The command that holds ``out_dir``'s reservation in this process, if any."""
    reservation = _held.get(Path(out_dir).resolve())
    return None if reservation is None else reservation.command


def held_folders() -> frozenset[Path]:
    """The folders this process holds reserved right now."""
    return frozenset(_held)


def release_left(before: frozenset[Path]) -> None:
    """Release every reservation taken since ``before`` (``held_folders()`` then) that this
    process still holds, whatever its count: the command line's last step after a Ctrl-C or
    SIGTERM. A signal can land in the few bytecodes between a ``reserved`` block's end and
    its release's deferral (CI, session 29: ``.out.flexcal-lock`` was left after a Ctrl-C
    right after a run's last line); then no block is left to let go of the lock."""
    with interrupts_deferred(), _held_guard:
        for out in [out for out in _held if out not in before]:
            _drop(out)


def _drop(out: Path) -> None:
    """``out``'s reservation out of ``_held`` and its lock released (``_held_guard`` held)."""
    reservation = _held.pop(out)
    _release(reservation.lock, reservation.text)
    if not out.exists():
        _remove_empty(reservation.made)


def _make_parents(folder: Path) -> list[Path]:
    missing = []
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    for path in reversed(missing):
        path.mkdir(exist_ok=True)
    return missing


def _acquire(out: Path, command: str, shown: str) -> _Reservation:
    """Take ``out``'s lock (``shown``: the folder as the user named it, for messages)."""
    inside, beside = lock_paths(out)
    text = _lock_text(command)
    made: list[Path] = []
    if out.is_dir():
        primary, other = inside, beside
    else:
        made = _make_parents(beside.parent)
        primary, other = beside, inside
    try:
        _take(shown, primary, text)
    except BaseException:
        _remove_empty(made)
        raise
    holder = read_holder(other)  # a run that locked the other place (the folder appeared or went meanwhile)
    if isinstance(holder, Holder) and holder.alive and not (holder.pid == os.getpid() and holder.host == host_hash()):
        _release(primary, text)
        _remove_empty(made)
        raise _refusal(shown, other, holder)
    return _Reservation(lock=primary, text=text, command=command, made=made)


def _remove_empty(folders: list[Path]) -> None:
    for folder in folders:  # deepest first
        with contextlib.suppress(OSError):
            folder.rmdir()


@contextlib.contextmanager
def reserved(out_dir: str | os.PathLike, *, command: str) -> Iterator[Path]:
    """Hold ``out_dir``'s lock for the block (see the module doc); yields the resolved
    folder path. OutInUse (a ValueError) if another live run holds it."""
    out = Path(out_dir).resolve()
    reservation = None
    try:
        # Ctrl-C and SIGTERM held back while the lock is taken and released (a Ctrl-C just after
        # a run's last line landed in the release and left the lock behind); one held back
        # while taking it is delivered here, with the lock recorded, so the release below runs
        with interrupts_deferred(), _held_guard:
            reservation = _held.get(out)
            if reservation is not None:
                reservation.count += 1
            else:
                reservation = _held[out] = _acquire(out, command, str(out_dir))
        yield out
    finally:
        if reservation is not None:  # None: not taken (OutInUse, an error)
            _let_go(out, reservation)


def _let_go(out: Path, reservation: _Reservation) -> None:
    """One ``reserved`` block's end: the count down, the lock released with the last one,
    interrupts held back meanwhile. A Ctrl-C or SIGTERM can still land in the few bytecodes
    before the deferral is in place (CI, session 16: the lock was left after a Ctrl-C just
    after the run's last line); then the release is done all the same and the signal's
    exception raised after it. The body runs once: it cannot be interrupted (deferred), and a
    second pass after a signal finds it done."""
    done = False
    pending: BaseException | None = None
    for _attempt in range(3):  # a signal before the deferral, one more delivered after it
        try:
            with interrupts_deferred(), _held_guard:
                if not done and _held.get(out) is reservation:  # else released already (release_left)
                    reservation.count -= 1
                    if reservation.count == 0:
                        _drop(out)
                done = True
            break
        except BaseException as stop:  # noqa: BLE001 - only the signals' exceptions are held
            if isinstance(stop, Exception):
                raise
            pending = pending or stop
    if pending is not None:
        raise pending


@contextlib.contextmanager
def reserved_out(out_dir: str | os.PathLike, *, command: str, replace: bool = False, resume: bool = False,
                 inputs: Iterable[tuple[str, Any]] = ()) -> Iterator[Path]:
    """The command line's hold on ``--out`` for the whole command: the lock first (a
    second run is told the folder is in use, whatever the folder holds), then
    ``output.out_folder``'s checks under it (nothing can change the folder now). A
    folder that cannot be locked because it cannot be written gets ``out_folder``'s line."""
    from .run_folder import out_folder

    inputs = list(inputs)
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(reserved(out_dir, command=command))
        except OutInUse:
            raise
        except OSError:
            out_folder(out_dir, replace=replace, resume=resume, inputs=inputs)  # says why, in one line
            raise
        yield out_folder(out_dir, replace=replace, resume=resume, inputs=inputs)
