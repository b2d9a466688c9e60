"""The consistent model's map, equilibrium and offsets' problems with the six chains as vector
lanes (``model/_consistent_map.c``).

``_numba_consistent._terms`` runs the chains one after another on scalars: numba's LLVM does not
vectorize across them (its SLP pass is off, numba PR 8852; an 8-wide loop is unrolled before the
loop vectorizer sees it). The C copies run every product on the six chains at once, and the
consistent kernel calls them by their symbols (``numba.types.ExternalFunction``), so numba still
caches the kernel: the symbols are resolved when the cached code is loaded, after ``AVAILABLE``
below has loaded the library into the process. Measured per evaluation of the map (one
process, 10^6 calls): 0.09-0.10 us with AVX-512 against numba's 0.33 us (docs/model.md 10,
"Session 42"). The lanes are two halves of four (one AVX2 register each; session 44): as one
8-wide vector they were registers with AVX-512 only, and the kernel ran 2.1x slower on an AVX2
machine.

Where the extension was not built (no C compiler at install), the symbols are bound to
placeholders that are never called, and the kernel runs numba's copies (``AVAILABLE`` False).
The two give the same numbers to rounding (tests/test_consistent_native.py), not the same bits.
"""

from __future__ import annotations

import importlib.util

import llvmlite.binding as llvm
from numba import cfunc, types

_DOUBLES = types.CPointer(types.float64)
_LONGS = types.CPointer(types.int64)
TERMS = "flexcal_consistent_terms"
# (cand, n_rows, lanes, x, c, command, x0, weight, n_terms, defect_index, symmetric, r, u, n, force)
TERMS_SIGNATURE = types.void(types.int64, types.int64, _DOUBLES, _DOUBLES, _DOUBLES, _DOUBLES, _DOUBLES, _DOUBLES,
                             types.int64, _LONGS, types.int64, _DOUBLES, _DOUBLES, _DOUBLES, _DOUBLES)
terms = types.ExternalFunction(TERMS, TERMS_SIGNATURE)
# the kernel's two: every array as its address (an array's ``.ctypes`` at each call cost a
# reference count pair), the candidate's read-only ones in an int64 context, CONTEXT's slots in
# ``_consistent_map.c``'s order (its ``CX_*``)
# (``stride``: the lane rows from one candidate's block to the next, 0 where ``lanes`` is the one
# candidate's block, as the kernel passes it)
CONTEXT = ("cand", "stride", "lanes", "x0", "weight", "n_terms", "defect_index", "symmetric")
EQUILIBRIUM = "flexcal_consistent_equilibrium"
# (context, x, c, n, r, u, force, secant, inputs, p, tol, max_iter, divergence, settle)
#   -> 4 x evaluations + status
EQUILIBRIUM_SIGNATURE = types.int64(*(types.intp,) * 9, types.int64, types.float64, types.int64, types.float64,
                                    types.int64)
equilibrium = types.ExternalFunction(EQUILIBRIUM, EQUILIBRIUM_SIGNATURE)
OFFSETS = "flexcal_consistent_offsets"
# (a, b, lo, hi, c_prev, band, side, status, tol, c, play, fresh) -> 1 solved, 0 failed
OFFSETS_SIGNATURE = types.int64(*(types.intp,) * 8, types.float64, types.intp, types.int64, types.int64)
offsets = types.ExternalFunction(OFFSETS, OFFSETS_SIGNATURE)


def _load() -> bool:
    spec = importlib.util.find_spec("flexcal.model._consistent_map")
    if spec is not None and spec.origin:
        llvm.load_library_permanently(spec.origin)
        return True

    # placeholders that are never called (the kernel takes numba's copies where AVAILABLE is False),
    # so that the kernel's code links
    @cfunc(TERMS_SIGNATURE)
    def no_terms(cand, n_rows, lanes, x, c, command, x0, weight, n_terms, defect_index, symmetric, r, u, n, force):
        pass

    @cfunc(EQUILIBRIUM_SIGNATURE)
    def no_equilibrium(context, x, c, n, r, u, force, secant, inputs, p, tol, max_iter, divergence, settle):
        return -1

    @cfunc(OFFSETS_SIGNATURE)
    def no_offsets(a, b, lo, hi, c_prev, band, side, status, tol, c, play, fresh):
        return 0

    _load.placeholders = (no_terms, no_equilibrium, no_offsets)  # kept alive with the process
    for name, placeholder in zip((TERMS, EQUILIBRIUM, OFFSETS), _load.placeholders):
        llvm.add_symbol(name, placeholder.address)
    return False


AVAILABLE = _load()
