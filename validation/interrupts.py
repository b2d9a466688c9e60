"""Ctrl-C and SIGTERM held back for a few steps that must not be cut halfway: the final
moves of a run's files into ``--out`` (``output.staged_output``) and the taking and
releasing of ``--out``'s lock (``out_lock.reserved``)."""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from typing import Any, Iterator

__all__ = ["interrupts_deferred"]


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
