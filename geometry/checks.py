"""Checks of parameter values, shared by every parameter type (``params.py``, ``profiles/``).

Each raises ``ValueError`` naming the parameter, its value (shown in mm for lengths) and
what it must be, so the user knows which input to change.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["require", "require_finite"]


def require(condition: bool, name: str, value: float, allowed: str, unit: str = "mm") -> None:
    """Raise ``ValueError`` naming the parameter, its value and the allowed range
    (``value`` [m] is shown in mm when ``unit`` is "mm")."""
    if not condition:
        shown = value * 1e3 if unit == "mm" else value
        raise ValueError(f"{name}={shown:.6g} {unit} is out of range: must be {allowed}")


def require_finite(name: str, value: float) -> None:
    """Raise ``ValueError`` unless ``value`` is a finite real number."""
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(float(value))):
        raise ValueError(f"{name}={value!r} must be a finite number")
