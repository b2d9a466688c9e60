"""Mapped-mesh outline of the circular notch hinge: no flat part, arcs of radius R."""

from __future__ import annotations

import functools

from . import MappedOutline
from ._arc import arc_height

__all__ = ["mapped_outline"]


def mapped_outline(hinge) -> MappedOutline:
    """Every notch hinge maps: its outline is one profile t(x)."""
    rho, t = hinge.radius, hinge.thickness
    return MappedOutline(flat_half_length=0.0, arc_half_length=rho, neck_thickness=t, block_length=hinge.block_length,
                         block_height=t + 2 * rho, width=hinge.width,
                         height=functools.partial(arc_height, c=0.0, rho=rho, t=t))
