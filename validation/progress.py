"""Progress on long runs, for every module that computes: a tqdm bar on a terminal, one log
line per stage with the elapsed time elsewhere (CI logs, nohup, a pipe).

This module holds no command-line logic, so numerics modules import it freely; the
command line (``flexcal.validation.cli``) imports it first, so elapsed times count from
the command's start.
"""

from __future__ import annotations

import sys
import time
from typing import Any, Callable

import numpy as np

__all__ = ["progress_bar", "progress_iter", "LineProgress", "stage_advancer", "with_progress", "LINE_INTERVAL_S"]

_STARTED = time.monotonic()  # the command's start (this module loads first): elapsed times in log lines
LINE_INTERVAL_S = 30.0  # off a terminal, a running count is logged at most this often


class LineProgress:
    """Progress for logs (stderr not a terminal: CI, nohup, a pipe): one line when a bar
    starts, when its stage changes (``set_description``), at most every
    ``LINE_INTERVAL_S`` while it counts, and when it ends, each with the time since the
    command started. The part of tqdm's interface flexcal uses (``update``,
    ``set_description``, ``close``, iteration, ``with``)."""

    def __init__(self, iterable=None, *, total: int | None = None, desc: str = "", unit: str = "it", stream=None):
        self.iterable, self.total, self.desc, self.unit = iterable, total, desc, unit
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            self.total = len(iterable)
        self.n, self._stream = 0, stream
        self._started = self._last_line = self._stage_started = time.monotonic()
        self._closed = False
        self._line(f"{desc}: started" + (f", {self.total} {unit}" if self.total else ""))

    def _line(self, text: str) -> None:
        stream = self._stream or sys.stderr
        print(f"[{time.monotonic() - _STARTED:8.1f} s] {text}", file=stream, flush=True)
        self._last_line = time.monotonic()

    def _count(self) -> str:
        return f"{self.n}/{self.total} {self.unit}" if self.total else f"{self.n} {self.unit}"

    def update(self, n: int = 1) -> None:
        self.n += n
        if time.monotonic() - self._last_line >= LINE_INTERVAL_S:
            self._line(f"{self.desc}: {self._count()}")

    def set_description(self, desc: str, refresh: bool = True) -> None:
        now = time.monotonic()
        self._line(f"{desc} (previous stage {self.desc}: {now - self._stage_started:.1f} s)")
        self.desc, self._stage_started = desc, now

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._line(f"{self.desc}: done, {self._count()} in {time.monotonic() - self._started:.1f} s")

    def __iter__(self):
        for item in self.iterable:
            yield item
            self.update(1)
        self.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        if exc[0] is None:
            self.close()


def _stderr_is_terminal() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def progress_bar(total: int | None, desc: str, *, enabled: bool = True, unit: str = "it"):
    """A tqdm bar on stderr when stderr is a terminal; off a terminal one log line per
    stage with the elapsed time (``LineProgress``); nothing with ``enabled=False``."""
    from tqdm import tqdm

    if enabled and not _stderr_is_terminal():
        return LineProgress(total=total, desc=desc, unit=unit)
    return tqdm(total=total, desc=desc, unit=unit, disable=not enabled, leave=False, dynamic_ncols=True)


def progress_iter(iterable, desc: str, *, enabled: bool = True, unit: str = "it", total: int | None = None):
    """``iterable`` with progress shown as ``progress_bar`` shows it."""
    from tqdm import tqdm

    if enabled and not _stderr_is_terminal():
        return LineProgress(iterable, total=total, desc=desc, unit=unit)
    return tqdm(iterable, total=total, desc=desc, unit=unit, disable=not enabled, leave=False, dynamic_ncols=True)


def stage_advancer(bar) -> Callable[[str], None]:
    """``stage(name)`` for staged jobs (CAD -> mesh -> solve -> report): each call closes
    the previous stage on ``bar`` and shows the new one's name."""
    started = [False]

    def stage(name: str) -> None:
        if started[0]:
            bar.update(1)
        started[0] = True
        bar.set_description(name)

    return stage


def with_progress(function: Callable[[np.ndarray], Any], bar) -> Callable[[np.ndarray], Any]:
    """A batched function ``(n, d) -> ...`` that advances ``bar`` by n rows per call."""

    def counted(x: np.ndarray):
        result = function(x)
        bar.update(int(np.shape(x)[0]))
        return result

    return counted
