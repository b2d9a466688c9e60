"""Mapped-mesh outline of the elliptical notch hinge: no flat part, a half ellipse each side."""

from __future__ import annotations

import numpy as np

from . import MappedOutline

__all__ = ["mapped_outline"]


def mapped_outline(hinge) -> MappedOutline:
    """Every elliptical notch hinge maps: its outline is one profile t(x); the grid's x
    lines follow x = a sin(phi), the ellipse's own angle."""
    a, b, t = hinge.semi_axis_x, hinge.semi_axis_y, hinge.thickness

    def height(x: np.ndarray) -> np.ndarray:
        u = np.clip(np.abs(x) / a, 0.0, 1.0)
        return t + 2.0 * b * (1.0 - np.sqrt(np.maximum(1.0 - u * u, 0.0)))

    return MappedOutline(flat_half_length=0.0, arc_half_length=a, neck_thickness=t, block_length=hinge.block_length,
                         block_height=t + 2.0 * b, width=hinge.width, height=height)
