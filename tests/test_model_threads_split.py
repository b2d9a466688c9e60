"""``model.threads.run_split``: every row in exactly one share, the first share in the calling
thread and the others on the pool, and an exception in any share reaching the caller only after
every share has finished (no share still writing into the caller's arrays)."""

import threading
import time

import numpy as np
import pytest

from flexcal.model.threads import run_split


@pytest.mark.parametrize("n, n_threads", [(1, 2), (7, 1), (7, 2), (8, 3), (3, 8)])
def test_every_row_is_in_exactly_one_contiguous_share(n, n_threads):
    counts = np.zeros(n, dtype=int)
    shares = []
    lock = threading.Lock()

    def rows(first, stop):
        with lock:
            shares.append((first, stop, threading.get_ident()))
            counts[first:stop] += 1

    run_split(rows, n, n_threads)
    np.testing.assert_array_equal(counts, 1)
    assert len(shares) == min(n, n_threads)
    first_share = min(shares)
    assert first_share[0] == 0 and first_share[2] == threading.get_ident()  # the caller runs the first share
    assert all(ident != threading.get_ident() for first, _, ident in shares if first != 0)


def test_the_callers_error_waits_for_the_other_shares():
    finished = []

    def rows(first, stop):
        if first == 0:
            raise RuntimeError("first share failed")
        time.sleep(0.2)  # [s] long enough that a caller not waiting would return before this share ends
        finished.append(first)

    with pytest.raises(RuntimeError, match="first share failed"):
        run_split(rows, 4, 2)
    assert finished == [2]


def test_a_pool_shares_error_reaches_the_caller():
    def rows(first, stop):
        if first > 0:
            raise ValueError(f"share at {first} failed")

    with pytest.raises(ValueError, match="share at 2 failed"):
        run_split(rows, 4, 2)
