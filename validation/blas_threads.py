"""Run small dense linear algebra on one BLAS thread.

The prototype factorizes a 153 x 153 tangent hundreds of times per trajectory. On a
shared 2-core machine a multi-threaded OpenBLAS makes such small factorizations 100 to
500 times slower than one thread (measured: Cholesky 0.24 s vs 0.5 ms under load), so
``simulate`` runs inside ``single_blas_thread()``. The context manager finds the OpenBLAS
libraries numpy and scipy have loaded (Linux: ``/proc/self/maps``), sets their thread
count to 1 and restores it on exit; where it cannot (other platforms, other BLAS) it
does nothing. ``threadpoolctl.threadpool_limits(1)`` does the same job more generally if
that package is installed.
"""

from __future__ import annotations

import contextlib
import ctypes
from typing import Iterator

__all__ = ["single_blas_thread"]

_PAIRS = [(f"{prefix}openblas_get_num_threads{suffix}", f"{prefix}openblas_set_num_threads{suffix}")
          for prefix in ("scipy_", "") for suffix in ("64_", "")]


def _openblas_controls() -> list[tuple]:
    paths = set()
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                if "openblas" in line.lower():
                    paths.add(line.split()[-1])
    except OSError:
        return []
    controls = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get_name, set_name in _PAIRS:
            getter, setter = getattr(lib, get_name, None), getattr(lib, set_name, None)
            if getter is not None and setter is not None:
                getter.restype = ctypes.c_int
                setter.argtypes = [ctypes.c_int]
                controls.append((getter, setter))
                break
    return controls


@contextlib.contextmanager
def single_blas_thread() -> Iterator[None]:
    """Limit the loaded OpenBLAS libraries to one thread inside the ``with`` block."""
    try:
        import threadpoolctl
    except ImportError:
        threadpoolctl = None
    if threadpoolctl is not None:
        with threadpoolctl.threadpool_limits(1, user_api="blas"):
            yield
        return
    import numpy  # noqa: F401  (make sure numpy's BLAS is loaded)
    import scipy.linalg  # noqa: F401

    controls = _openblas_controls()
    previous = [getter() for getter, _ in controls]
    for _, setter in controls:
        setter(1)
    try:
        yield
    finally:
        for (_, setter), count in zip(controls, previous):
            setter(max(int(count), 1))
