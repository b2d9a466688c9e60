"""The worker threads of the compiled model's batches: one pool for the process, and the split of a
batch's rows into contiguous shares, one per thread (the kernels hold no GIL, and each row is
computed on its own, so a row's bits do not depend on the split)."""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, wait


@functools.cache
def thread_pool() -> ThreadPoolExecutor:
    """The threads the compiled batches share their rows over, kept for the process (a pool per
    call cost a calibration's small batches their threads' start). Work submitted to it never
    submits to it again (no deadlock)."""
    return ThreadPoolExecutor(max_workers=os.cpu_count() or 1)


def run_split(rows: Callable[[int, int], object], n: int, n_threads: int) -> None:
    """``rows(first, stop)`` over ``n`` rows in contiguous shares, one per thread (at most
    ``n_threads``): the first share in this thread, the others on ``thread_pool``. (Session 45:
    with every share on the pool, two threads ran a few-ms share ~1.26x faster than one on the
    2-vCPU VM, the second share often queued for ~3 ms on the first one's core; with this thread
    taking a share, 1.72x, medians of 150 interleaved calls of the shortening forms; docs/model.md
    10.) If this thread's share raises, the others are waited for before the exception leaves."""
    threads = max(1, min(int(n_threads), n))
    bounds = [round(k * n / threads) for k in range(threads + 1)]
    others = [thread_pool().submit(rows, first, stop) for first, stop in zip(bounds[1:-1], bounds[2:])]
    try:
        rows(bounds[0], bounds[1])
    finally:
        wait(others)
    for share in others:
        share.result()
