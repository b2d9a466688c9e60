"""Ctrl-C and SIGTERM as exceptions, so every ``finally`` runs (staging folders removed).

Python turns SIGINT into ``KeyboardInterrupt``; SIGTERM (``kill PID``, a batch system's
time limit, ``docker stop``) kills the process at once by default, leaving staging
folders beside ``--out`` behind. ``termination_raises()`` makes SIGTERM raise
``Terminated`` (a ``KeyboardInterrupt``, so every clean-up written for Ctrl-C also runs
for it); the command line exits 130 on SIGINT and 143 on SIGTERM (128 + the signal
number, what a shell reports for a process killed by it).

Libraries that reset the SIGINT handler (pytetwild) run in a child process
(``flexcal.fem.tetwild_process``).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator

__all__ = ["Terminated", "termination_raises", "exit_status", "HANDLED_SIGNALS"]

HANDLED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM."""


def _raise_terminated(signum, frame):
    raise Terminated(f"received signal {signal.Signals(signum).name}")


@contextlib.contextmanager
def termination_raises() -> Iterator[None]:
    """Inside the block SIGTERM raises ``Terminated`` (main thread only; elsewhere a
    no-op, Python delivers signals to the main thread). The previous handler is put back."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def exit_status(interrupt: KeyboardInterrupt) -> int:
    """143 for SIGTERM (``Terminated``), 130 for Ctrl-C."""
    return 128 + (signal.SIGTERM if isinstance(interrupt, Terminated) else signal.SIGINT)
