"""Ctrl-C and SIGTERM: the record of what was received, and a few steps held back from them.

``Terminated`` is SIGTERM as an exception (a ``KeyboardInterrupt``, so every clean-up written
for Ctrl-C also runs for it); ``flexcal.validation.cli.signals.termination_raises`` raises it
and records every signal it turns into an exception (``record_received``). A library can
swallow that exception: one raised inside a destructor or a C callback (VTK's
``DataObject.__del__`` while pictures render) is only "ignored" by Python, and the run would
go on and publish its results as if nobody had asked it to stop. ``raise_received`` raises
the recorded interrupt again; ``output.staged_output`` calls it before anything moves into
``--out``.

``interrupts_deferred`` holds both signals back for a few steps that must not be cut
halfway: the final moves of a run's files into ``--out`` (``output.staged_output``) and the
taking and releasing of ``--out``'s lock (``out_lock.reserved``).
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from typing import Any, Iterator

__all__ = ["Terminated", "interrupts_deferred", "record_received", "forget_received", "take_received",
           "received_interrupt", "raise_received"]


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM."""


_received: list[int] = []  # signals turned into exceptions inside termination_raises()


def record_received(signum: int) -> None:
    """Note a Ctrl-C or SIGTERM that is being raised as an exception."""
    _received.append(signum)


def forget_received() -> None:
    """A fresh record (a new ``termination_raises`` block)."""
    del _received[:]


def take_received() -> int | None:
    """The first signal recorded, or None; forgotten once taken."""
    signum = _received[0] if _received else None
    forget_received()
    return signum


def received_interrupt() -> KeyboardInterrupt | None:
    """The first recorded signal as its exception (``Terminated`` or ``KeyboardInterrupt``),
    or None."""
    if not _received:
        return None
    return Terminated("received signal SIGTERM") if _received[0] == signal.SIGTERM else KeyboardInterrupt()


def raise_received() -> None:
    """Raise the recorded interrupt, if any: the run was asked to stop, even if a library
    swallowed the exception that said so (module doc)."""
    interrupt = received_interrupt()
    if interrupt is not None:
        raise interrupt


@contextlib.contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Hold back Ctrl-C (SIGINT) and SIGTERM inside the block and deliver the first one
    right after (to the handler that was there before); a no-op off the main thread
    (where Python never delivers signals anyway). A signal that was ignored stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[tuple[int, Any]] = []
    previous = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(signum)
        if handler is not None and handler is not signal.SIG_IGN:  # None: set outside Python, leave it
            previous[signum] = signal.signal(signum, lambda number, frame: received.append((number, frame)))
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if received:
        signum, frame = received[0]
        handler = previous[signum]
        if callable(handler):
            handler(signum, frame)
        elif signum == signal.SIGINT:
            raise KeyboardInterrupt
        else:  # SIG_DFL (or a handler not set from Python): let the system act on it
            os.kill(os.getpid(), signum)
