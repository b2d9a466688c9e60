"""The worker threads of the compiled model's batches: one pool for the process, and the split of a
batch's rows into contiguous shares, one per thread (the kernels hold no GIL, and each row is
computed on its own, so a row's bits do not depend on the split)."""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor


@functools.cache
def thread_pool() -> ThreadPoolExecutor:
    """The threads the compiled batches share their rows over, kept for the process (a pool per
    call cost a calibration's small batches their threads' start). Work submitted to it never
    submits to it again (no deadlock)."""
    return ThreadPoolExecutor(max_workers=os.cpu_count() or 1)


def run_split(rows: Callable[[int, int], object], n: int, n_threads: int) -> None:
    """``rows(first, stop)`` over ``n`` rows in contiguous shares, one per thread (at most
    ``n_threads``), on ``thread_pool``; in this thread when one share."""
    threads = max(1, min(int(n_threads), n))
    bounds = [round(k * n / threads) for k in range(threads + 1)]
    if threads == 1:
        rows(0, n)
    else:
        list(thread_pool().map(rows, bounds[:-1], bounds[1:]))
