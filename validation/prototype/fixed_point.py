"""Anderson acceleration of the prototype's nut-offset fixed point (bounded, safeguarded).

The nut offsets g of the three drives solve g = F(g) (``transmission.nut_offset`` after an
equilibrium). F contracts, but slowly when two driving chains are off their flanks at
once: their offsets move against each other with a factor of ~0.7 per round (measured on
the user scenario ``name = "x"``, seed 1, point 19: 30 plain rounds left a change of
6 nm against the 1e-12 m tolerance). Anderson acceleration (type II, Walker & Ni 2011)
fits the last few residuals r = F(g) - g linearly and jumps to where they vanish: exact
in n + 1 rounds for an affine F in n unknowns, and F is piecewise affine here. Each step
is clipped to the offsets' range [0, CL]; where the fit does not help (the last residual
grew, a kink of the play operator or the clearance wall) the step falls back to the
damped one, 0.5 (g + F(g)), and the memory restarts.
"""

from __future__ import annotations

import numpy as np

__all__ = ["anderson_step"]


def anderson_step(iterates: list[np.ndarray], images: list[np.ndarray], upper: np.ndarray, *,
                  memory: int = 3) -> tuple[np.ndarray, bool]:
    """Next iterate of g = F(g) from the iterates g_i and their images F(g_i) (lists of
    (n,) [m], oldest first, at least one). Returns (next iterate clipped to [0, upper],
    restart): ``restart`` True means the damped step was taken and the caller should
    clear its history."""
    g = np.asarray(iterates[-(memory + 1):], dtype=float)
    f = np.asarray(images[-(memory + 1):], dtype=float)
    damped = np.clip(0.5 * (g[-1] + f[-1]), 0.0, upper)
    residual = f - g
    if len(g) < 2:
        return damped, False
    if np.linalg.norm(residual[-1]) > np.linalg.norm(residual[-2]):
        return damped, True
    d_residual = np.diff(residual, axis=0).T  # (n, m)
    d_image = np.diff(f, axis=0).T
    # rcond: differences below 1e-10 of the largest carry only round-off of the equilibrium
    gamma = np.linalg.lstsq(d_residual, residual[-1], rcond=1e-10)[0]
    step = f[-1] - d_image @ gamma
    if not np.all(np.isfinite(step)):
        return damped, True
    return np.clip(step, 0.0, upper), False
