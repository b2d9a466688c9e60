"""Mapped-mesh outline of the corner-filleted leaf hinge: flat neck, fillet arcs of radius a."""

from __future__ import annotations

import functools

from . import MappedOutline
from ._arc import arc_height

__all__ = ["mapped_outline"]


def mapped_outline(hinge) -> MappedOutline | None:
    """A leaf maps when its blocks are as high as its fillets reach (t + 2a, the default):
    then its outline is one profile t(x); higher blocks have steps (None)."""
    if hinge.height > hinge.thickness + 2 * hinge.fillet + 1e-12:
        return None
    c, rho, t = hinge.length / 2 - hinge.fillet, hinge.fillet, hinge.thickness
    return MappedOutline(flat_half_length=c, arc_half_length=rho, neck_thickness=t, block_length=hinge.block_length,
                         block_height=t + 2 * rho, width=hinge.width,
                         height=functools.partial(arc_height, c=c, rho=rho, t=t))
