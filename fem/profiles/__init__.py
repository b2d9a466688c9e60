"""What the FEM needs per hinge profile: the outline the mapped mesher maps onto.

One module per profile, named as the profile (``flexcal.geometry.profiles``), each with
``mapped_outline(hinge) -> MappedOutline | None`` (None: this hinge cannot be mapped,
e.g. a leaf whose blocks are higher than its fillets reach). ``fem.mesh_mapped`` finds it
through ``outline_of(hinge)``; a new profile adds its module here and nothing else in fem.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from flexcal.geometry.profiles import discover

__all__ = ["MappedOutline", "outline_of"]


@dataclass(frozen=True, kw_only=True, eq=False)
class MappedOutline:
    """A single hinge as one height profile h(x) extruded along its width, for the mapped mesher.

    Hinge frame, [m]: a flat neck of half-length ``flat_half_length`` (c) and thickness
    ``neck_thickness`` (t), then on each side a curved part reaching ``arc_half_length``
    further along x (the grid places its x lines at x = c + arc_half_length sin(phi)),
    then the blocks (``block_length`` long, ``block_height`` high); ``width`` along z.
    ``height(x)`` gives the local height (x any shape) [m], ``block_height`` beyond the arcs.
    """

    flat_half_length: float
    arc_half_length: float
    neck_thickness: float
    block_length: float
    block_height: float
    width: float
    height: Callable[[np.ndarray], np.ndarray]


def outline_of(hinge) -> MappedOutline | None:
    """The mapped-mesh outline of ``hinge`` from its profile's fem module, or None when the
    profile has none or this hinge cannot be mapped."""
    name = getattr(hinge, "profile_name", None)
    make = discover("flexcal.fem.profiles", "mapped_outline").get(name)
    return None if make is None else make(hinge)
