"""The mount's linearized buckling factor checked by the prototype's own nonlinear solve.

``mount_buckling_factor`` predicts the factor s on the payload's weight at which the
tangent turns singular from K_0 + s (K_T(1) - K_0). Here Newton solves the equilibrium at
increasing weight factors (continuation: each from the last state; nuts on their
actuator springs, design commands) and at each converged state takes the lowest
eigenvalue mu of K_T(s) phi = mu K_0 phi (K_0 the unloaded tangent: mu is the fraction of
the unloaded stiffness left in the softest direction; the linearization says
mu = 1 - s / s_cr). The nonlinear buckling factor is where mu reaches zero (interpolated
between the last two states, or Newton stops converging just beyond it). The two differ
by the pre-buckling deformation the linearization leaves out.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg

from ..prototype.equilibrium import NonConvergenceError
from ..prototype.mechanism import Prototype
from .mount import nominal_state

__all__ = ["DEFAULT_FACTORS", "newton_buckling_scan"]

DEFAULT_FACTORS = (1.0, 10.0, 20.0, 30.0, 40.0, 50.0, 55.0, 60.0, 70.0, 80.0, 90.0, 100.0, 110.0, 120.0, 130.0,
                   140.0, 150.0, 175.0, 200.0)
"""Weight factors scanned, through the linearized ~50-55 and on: the nonlinear path
stiffens (measured: mu = 0.08 still at 80), so the scan goes to 200."""


def _symmetric(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + a.T)


def newton_buckling_scan(prototype: Prototype, factors=DEFAULT_FACTORS, *, bisections: int = 4) -> dict[str, Any]:
    """{"factors", "lowest_eigenvalue" (mu at each converged factor of ``factors``),
    "newton_converged_to" / "newton_failed_at" (after ``bisections`` halvings between the
    last converged factor and the first that failed, each from the last converged state;
    failed None if all converged), "zero_crossing" (the factor where mu reaches 0, linear
    through the last two mu: interpolated if the last is <= 0, else extrapolated; None if
    mu does not fall), "linear_prediction" (where 1 - s / s_cr through the first two
    points reaches 0: the linearized factor as this scan sees it)} (module docstring)."""
    K0 = _symmetric(nominal_state(prototype, 0.0).tangent)
    done, mu, failed = [], [], None
    poses = None
    for s in sorted(float(f) for f in factors):
        try:
            state = nominal_state(prototype, s, start=poses)
        except NonConvergenceError:
            failed = s
            break
        poses = state.poses
        done.append(s)
        mu.append(float(scipy.linalg.eigh(_symmetric(state.tangent), K0, eigvals_only=True, subset_by_index=[0, 0])[0]))
        if mu[-1] <= 0.0:
            break
    last_converged = done[-1] if done else None
    if failed is not None and poses is not None:  # bisect where Newton stops converging
        low, high = done[-1], failed
        for _ in range(bisections):
            middle = 0.5 * (low + high)
            try:
                nominal_state(prototype, middle, start=poses)
                low = middle
            except NonConvergenceError:
                high = middle
        last_converged, failed = low, high
    crossing = None
    if len(mu) >= 2:  # mu reaches zero: between the last two states, or extrapolated from them
        s0, s1, m0, m1 = done[-2], done[-1], mu[-2], mu[-1]
        crossing = s0 + (s1 - s0) * m0 / (m0 - m1) if m1 < m0 else None
    linear = None
    if len(mu) >= 2 and mu[0] != mu[1]:
        slope = (mu[1] - mu[0]) / (done[1] - done[0])
        linear = done[0] - mu[0] / slope if slope < 0 else None
    return {"factors": done, "lowest_eigenvalue": mu, "newton_converged_to": last_converged,
            "newton_failed_at": failed, "zero_crossing": crossing,
            "linear_prediction": linear}
