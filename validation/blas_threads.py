"""Run small dense linear algebra on one BLAS thread.

The prototype factorizes a 153 x 153 tangent hundreds of times per trajectory. On a
shared 2-core machine a multi-threaded OpenBLAS makes such small factorizations 100 to
500 times slower than one thread (measured: Cholesky 0.24 s vs 0.5 ms under load), so
``simulate`` runs inside ``single_blas_thread()`` (threadpoolctl).
"""

from __future__ import annotations

import contextlib
from typing import Iterator

from threadpoolctl import threadpool_limits

__all__ = ["single_blas_thread", "blas_threads"]


@contextlib.contextmanager
def blas_threads(n_threads: int) -> Iterator[None]:
    """Limit the loaded BLAS libraries' global pools to ``n_threads`` inside the ``with``
    block (the process's: threadpoolctl)."""
    with threadpool_limits(n_threads, user_api="blas"):
        yield


def single_blas_thread():
    """Limit the loaded BLAS libraries to one thread inside the ``with`` block."""
    return blas_threads(1)
