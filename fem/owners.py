"""Folders that name the process that made them, so a later run can remove the folders of
a process that died where it could not clean up (SIGKILL, the OOM killer, a Dask worker
ended by its nanny).

A folder's name carries ``owner_tag()``: a hash of the host name, the process id and, on
Linux, the process's start time (``HOST-PID-START``). ``remove_folders_of_gone_owners``
removes the folders in one place whose name matches a pattern with those three groups
and whose owner, on this host, is gone; a live process's folder, another host's (a
shared file system: its process ids mean nothing here) and folders of other names are
never touched. Used by the command line's staging folders (``validation/output.py``)
and fTetWild's scratch folders (``tetwild_process.py``); the lock that reserves ``--out``
records ``owner_tag()`` in its text and tests it with ``owner_alive``
(``validation/out_lock.py``).
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import socket
from pathlib import Path

__all__ = ["OWNER_TAG", "host_hash", "owner_alive", "owner_tag", "process_state", "remove_folders_of_gone_owners"]

# the regular expression of owner_tag(): groups host hash, process id, start time
OWNER_TAG = r"([0-9a-f]{8})-(\d+)-(\d+)"


def host_hash() -> str:
    """8 hex digits naming this host in folder names."""
    return hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]


def process_state(pid: int) -> tuple[str, int] | None:
    """(state letter, start time in clock ticks after boot) of a process from
    /proc/PID/stat; None where there is no /proc (not Linux) or no such process."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2:].split()  # after "pid (command) ": state is field 3, starttime 22
    return fields[0], int(fields[19])


def owner_tag() -> str:
    """``HOST-PID-START`` of this process (START 0 where there is no /proc)."""
    state = process_state(os.getpid())
    return f"{host_hash()}-{os.getpid()}-{state[1] if state else 0}"


def owner_alive(pid: int, start: int) -> bool:
    """Whether the process that made a folder (this host's ``pid``, started at ``start``;
    0 = unknown) still runs. In doubt, alive."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # another user's live process
    state = process_state(pid)
    if state is None:
        return True  # no /proc: the pid exists, so assume it is the owner
    letter, started = state
    if letter in ("Z", "X"):  # killed, not yet reaped by its parent
        return False
    return start == 0 or started == start  # a different start: the pid was reused


def remove_folders_of_gone_owners(folder: str | os.PathLike, name: re.Pattern) -> list[str]:
    """Remove the folders in ``folder`` whose name matches ``name`` (a pattern whose groups
    1-3 are ``OWNER_TAG``'s) and whose owner, on this host, is gone; returns their names.
    Errors are ignored (a folder that cannot be removed stays as it was)."""
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    host = host_hash()
    for entry in entries:
        match = name.match(entry.name)
        if not match or match.group(1) != host or not entry.is_dir(follow_symlinks=False):
            continue
        pid, start = int(match.group(2)), int(match.group(3))
        if pid == os.getpid() or owner_alive(pid, start):
            continue
        shutil.rmtree(entry.path, ignore_errors=True)
        if not os.path.lexists(entry.path):
            removed.append(entry.name)
    return removed
