"""Ctrl-C and SIGTERM as exceptions, so every ``finally`` runs (staging folders removed).

Python turns SIGINT into ``KeyboardInterrupt``; SIGTERM (``kill PID``, a batch system's
time limit, ``docker stop``) kills the process at once by default, leaving staging
folders beside ``--out`` behind. ``termination_raises()`` makes SIGTERM raise
``Terminated`` (a ``KeyboardInterrupt``, so every clean-up written for Ctrl-C also runs
for it); the command line exits 130 on SIGINT and 143 on SIGTERM (128 + the signal
number, what a shell reports for a process killed by it). An error that an interrupt
caused (``interrupt_behind``) counts as that interrupt. Inside the block an interrupt that
Python could only report as "ignored" (raised in a destructor or a C callback) is not
printed: it is recorded (``flexcal.validation.interrupts``), and the run stops at its next
``staged_output`` step or at its end as if it had been raised.

Libraries that reset the SIGINT handler (pytetwild) run in a child process
(``flexcal.fem.tetwild_process``).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from typing import Iterator

from ..interrupts import Terminated, forget_received, received_interrupt, record_received

__all__ = ["Terminated", "termination_raises", "interrupt_behind", "exit_status", "HANDLED_SIGNALS"]

HANDLED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _raise_terminated(signum, frame):
    record_received(signum)
    raise Terminated(f"received signal {signal.Signals(signum).name}")


def _raise_interrupted(signum, frame):
    record_received(signum)
    raise KeyboardInterrupt


def _quiet_about_interrupts(default):
    """An ``unraisablehook`` that leaves out interrupts (recorded already, acted on later)
    and passes everything else to ``default``."""
    def hook(unraisable):
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            default(unraisable)
    return hook


@contextlib.contextmanager
def termination_raises() -> Iterator[None]:
    """Inside the block SIGTERM raises ``Terminated`` and Ctrl-C ``KeyboardInterrupt``
    (if Python's default handler is in place: an ignored SIGINT stays ignored), and both
    are recorded for ``interrupt_behind``; one swallowed as "ignored" is not printed (module
    doc). Main thread only (elsewhere a no-op: Python delivers signals to the main thread).
    The previous handlers and ``sys.unraisablehook`` are put back."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    forget_received()
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, _raise_terminated)}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, _raise_interrupted)
    unraisable_hook = sys.unraisablehook
    sys.unraisablehook = _quiet_about_interrupts(unraisable_hook)
    try:
        yield
    finally:
        sys.unraisablehook = unraisable_hook
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
    return received_interrupt()


def exit_status(interrupt: KeyboardInterrupt) -> int:
    """143 for SIGTERM (``Terminated``), 130 for Ctrl-C."""
    return 128 + (signal.SIGTERM if isinstance(interrupt, Terminated) else signal.SIGINT)
