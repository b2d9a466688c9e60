"""The height of a neck with circular arcs at its ends (circular notch, filleted leaf)."""

from __future__ import annotations

import numpy as np

__all__ = ["arc_height"]


def arc_height(x: np.ndarray, c: float, rho: float, t: float) -> np.ndarray:
    """Local height [m] at x [m]: t on the flat part |x| <= c, t + 2(rho - sqrt(rho^2 - u^2))
    on the arcs (u = |x| - c), t + 2 rho on the blocks."""
    u = np.clip(np.abs(x) - c, 0.0, rho)
    return t + 2.0 * (rho - np.sqrt(np.maximum(rho * rho - u * u, 0.0)))
