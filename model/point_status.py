"""Status codes of the per-point solve of Eq. 8 (one per candidate and point).

Written by the compiled kernel (``_numba_kernels.solve``) and read by ``forward``, which
turns a failed point into a ``ConvergenceError`` that names it.
"""

from __future__ import annotations

__all__ = ["OK", "NOT_CONVERGED", "DIVERGED", "CLEARANCE_FAILED"]

OK = 0  # converged: max |dv| <= tol at the point
NOT_CONVERGED = 1  # no convergence in max_iter iterations
DIVERGED = 2  # the parasitic/clearance iteration grew past the divergence bound
CLEARANCE_FAILED = 3  # the clearance box QP found no consistent state
