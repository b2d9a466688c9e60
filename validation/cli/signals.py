"""Ctrl-C and SIGTERM as exceptions, so every ``finally`` runs (staging folders removed).

Python turns SIGINT into ``KeyboardInterrupt``; SIGTERM (``kill PID``, a batch system's
time limit, ``docker stop``) kills the process at once by default, leaving staging
folders beside ``--out`` behind. ``termination_raises()`` makes SIGTERM raise
``Terminated`` (a ``KeyboardInterrupt``, so every clean-up written for Ctrl-C also runs
for it); the command line exits 130 on SIGINT and 143 on SIGTERM (128 + the signal
number, what a shell reports for a process killed by it). An error that an interrupt
caused (``interrupt_behind``) counts as that interrupt.

Libraries that reset the SIGINT handler (pytetwild) run in a child process
(``flexcal.fem.tetwild_process``).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator

__all__ = ["Terminated", "termination_raises", "interrupt_behind", "exit_status", "take_received_signal",
           "HANDLED_SIGNALS"]

HANDLED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM."""


_received: list[int] = []  # signals delivered while termination_raises() is active


def _raise_terminated(signum, frame):
    _received.append(signum)
    raise Terminated(f"received signal {signal.Signals(signum).name}")


def _raise_interrupted(signum, frame):
    _received.append(signum)
    raise KeyboardInterrupt


@contextlib.contextmanager
def termination_raises() -> Iterator[None]:
    """Inside the block SIGTERM raises ``Terminated`` and Ctrl-C ``KeyboardInterrupt``
    (if Python's default handler is in place: an ignored SIGINT stays ignored), and both
    are recorded for ``interrupt_behind``. Main thread only (elsewhere a no-op: Python
    delivers signals to the main thread). The previous handlers are put back."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    del _received[:]
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, _raise_terminated)}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, _raise_interrupted)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def interrupt_behind(error: BaseException) -> KeyboardInterrupt | None:
    """The interrupt that caused ``error``, if any: a ``KeyboardInterrupt`` in its chain of
    causes (an extension module whose initialisation was interrupted raises
    ``ImportError('initialization failed')`` from it), or else a signal received inside
    ``termination_raises`` (a library that swallowed the exception)."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    if _received:
        return Terminated() if _received[0] == signal.SIGTERM else KeyboardInterrupt()
    return None


def take_received_signal() -> int | None:
    """The first signal (SIGINT or SIGTERM) delivered inside the last ``termination_raises``
    block, or None; forgotten once taken."""
    signum = _received[0] if _received else None
    del _received[:]
    return signum


def exit_status(interrupt: KeyboardInterrupt) -> int:
    """143 for SIGTERM (``Terminated``), 130 for Ctrl-C."""
    return 128 + (signal.SIGTERM if isinstance(interrupt, Terminated) else signal.SIGINT)
