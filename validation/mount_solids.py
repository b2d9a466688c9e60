"""The mount as solids: its six chains placed in the mount frame, its payload box, and where
any two of them overlap (OpenCASCADE booleans through CadQuery).

``mount_solids(mechanism)`` gives the placed solids by name ("L1".."D3", and "payload"
when the mount file places the box: ``[payload] box_centre_mm``); ``overlaps(mechanism)``
the pairs whose solids share volume. Each pair's envelopes are compared first (a chain's:
the box around its axis A-B grown by its widest piece's half-diagonal; the payload's: its
box), so CadQuery is loaded, and the solids built and intersected, only for pairs that may
touch: the reference and mirror mounts need no boolean (~0.01 s of CPU); a pair that may
touch costs CadQuery's import (~1.7 s) and ~0.02 s per boolean.

A chain is fastened to the payload by its end block at B (the payload-frame side): that
block may sit inside the payload's box (a tilted chain's block corners do when its end B
is on the box's face); any other part of a chain inside the box is a collision.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from flexcal.geometry.exact import pieces
from flexcal.geometry.params import ChainPlacement, MechanismParams

if TYPE_CHECKING:
    import cadquery as cq

__all__ = ["Overlap", "mount_solids", "payload_solid", "envelopes", "overlaps", "MIN_OVERLAP", "PAYLOAD"]

PAYLOAD = "payload"
# A common volume below 1 mm^3 is not a collision: OpenCASCADE's booleans leave slivers of
# ~1e-18 m^3 where faces merely touch (a chain's end face flush on the payload's), while two
# sections of tens of mm that overlap by 1 mm along an edge share ~10^3 mm^3.
MIN_OVERLAP = 1e-9  # [m^3]


@dataclass(frozen=True, kw_only=True)
class Overlap:
    """Two bodies of the mount that share volume: ``first``, ``second`` (chain names or
    "payload"), ``volume`` [m^3] of their common solid, ``centre`` (3,) [m] its centroid in
    the mount frame."""

    first: str
    second: str
    volume: float
    centre: tuple[float, float, float]


def payload_solid(mechanism: MechanismParams, centre: tuple[float, float, float] | None = None) -> cq.Solid:
    """The payload's box [m] centred on ``centre`` (default: ``payload_box_centre``, which
    must then be set), edges along the mount axes."""
    import cadquery as cq

    centre = mechanism.payload_box_centre if centre is None else centre
    if centre is None:
        raise ValueError("the payload box is not placed: give [payload] box_centre_mm in the mount file")
    sides = np.asarray(mechanism.payload_box, float)
    corner = np.asarray(centre, float) - sides / 2
    return cq.Solid.makeBox(*sides, cq.Vector(*corner))


def mount_solids(mechanism: MechanismParams) -> dict[str, cq.Shape]:
    """The chains' solids placed in the mount frame [m] by name, in the order L1..D3, then
    "payload" (its box) when the mount places it."""
    from flexcal.geometry.solids import mechanism_assembly

    assembly = mechanism_assembly(mechanism)
    solids = {child.name: child.obj.moved(child.loc) for child in assembly.children}
    if mechanism.payload_box_centre is not None:
        solids[PAYLOAD] = payload_solid(mechanism)
    return solids


def _attachment(placement: ChainPlacement) -> cq.Solid:
    """The chain's end block at B placed in the mount frame [m]: where it is fastened to
    the payload."""
    import cadquery as cq

    from flexcal.geometry.solids import location

    block = pieces(placement.chain)[-1]
    local = cq.Solid.makeBox(block.x1 - block.x0, 2 * block.half_y, 2 * block.half_z,
                             cq.Vector(block.x0, -block.half_y, -block.half_z))
    return local.moved(location(placement.rotation, placement.point_a))


def envelopes(mechanism: MechanismParams) -> dict[str, np.ndarray]:
    """(2, 3) [m] lower and upper corners of an axis-aligned box around each body, by name
    as ``mount_solids``: a chain's solid lies within its axis A-B grown by the largest
    half-diagonal of its pieces' end sections (a piece is widest at its ends: blocks are
    prisms, a hinge narrows inward from its ends)."""
    out = {}
    for placement in mechanism.chains:
        reach = max(float(np.hypot(*piece.end_extent())) for piece in pieces(placement.chain))
        ends = np.array([placement.point_a, placement.point_b], float)
        out[placement.name] = np.array([ends.min(axis=0) - reach, ends.max(axis=0) + reach])
    if mechanism.payload_box_centre is not None:
        centre, half = np.asarray(mechanism.payload_box_centre, float), np.asarray(mechanism.payload_box, float) / 2
        out[PAYLOAD] = np.array([centre - half, centre + half])
    return out


def _apart(first: np.ndarray, second: np.ndarray) -> bool:
    return bool(np.any(first[1] < second[0]) or np.any(second[1] < first[0]))


def overlaps(mechanism: MechanismParams) -> list[Overlap]:
    """Every pair of the mount's bodies (chains; the payload box when placed) whose solids
    share more than ``MIN_OVERLAP``, in the order L1-L2, L1-L3, ..., D3-payload. A chain's
    end block at B (its attachment) does not count against the payload. Pairs whose
    ``envelopes`` are apart are not built."""
    boxes = envelopes(mechanism)
    pairs = [(a, b) for a, b in itertools.combinations(boxes, 2) if not _apart(boxes[a], boxes[b])]
    if not pairs:
        return []
    import cadquery as cq

    solids = mount_solids(mechanism)
    placements = {p.name: p for p in mechanism.chains}
    found = []
    for name_1, name_2 in pairs:
        common = solids[name_1].intersect(solids[name_2])
        if name_2 == PAYLOAD:
            common = common.cut(_attachment(placements[name_1]))
        volume = float(common.Volume())
        if volume > MIN_OVERLAP:
            centre = cq.Shape.centerOfMass(common)
            found.append(Overlap(first=name_1, second=name_2, volume=volume,
                                 centre=(float(centre.x), float(centre.y), float(centre.z))))
    return found
