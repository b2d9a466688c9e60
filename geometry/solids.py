"""CadQuery solids of flexure hinges, flexure chains and the six-chain mechanism.

Frames as in ``flexcal.geometry.params``; lengths in metres inside the CadQuery shapes
too (``flexcal.geometry.export`` converts to mm when writing files). A solid is built
from the pieces of ``flexcal.geometry.exact`` (blocks, leaves, notches along local x),
the same decomposition the mesher uses for the exact surfaces, so CAD and analytic
description cannot drift apart silently (tests compare them).

Parameter validation happens in the parameter dataclasses; the only extra check here is
a minimum feature size that the CAD kernel can resolve.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Union

import cadquery as cq
import numpy as np
from OCP.gp import gp_Trsf

from .exact import BoxPiece, LeafPiece, NotchPiece, end_planes, pieces, reference_points
from .params import ChainSegment, CircularNotchHinge, FlexureChain, LeafHinge, MechanismParams

__all__ = ["Part", "hinge_solid", "chain_solid", "segment_solid", "mechanism_assembly", "MIN_FEATURE_SIZE"]

#: Smallest dimension [m] the solids accept: 10x OpenCASCADE's confusion tolerance
#: (1e-7 model units = 0.1 um here), below which faces merge or booleans fail.
MIN_FEATURE_SIZE = 1e-6

Params = Union[CircularNotchHinge, LeafHinge, FlexureChain, ChainSegment]


@dataclass(frozen=True, kw_only=True, eq=False)
class Part:
    """A solid and what the FEM needs to know about it.

    shape: the CadQuery solid [m] in the part frame; params: the parameter object it was
    built from; reference_points: end-face centres (3,) [m] ("fixed"/"free" for hinges,
    "A"/"B" for chains); end_planes: ``name -> (point (3,) [m], outward unit normal (3,))``
    of the end faces the FEM couples to its reference points.
    """

    shape: cq.Shape
    params: Params
    reference_points: dict[str, np.ndarray] = field(default_factory=dict)
    end_planes: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    @property
    def volume(self) -> float:
        """Volume of the CAD solid [m^3]."""
        return float(self.shape.Volume())


def _check_feature_sizes(params: Params) -> None:
    """Raise ValueError if a non-zero dimension is below MIN_FEATURE_SIZE."""
    ps = pieces(params)
    sizes: dict[str, float] = {}
    for i, p in enumerate(ps):
        sizes[f"piece {i} length"] = p.x1 - p.x0
        if isinstance(p, (LeafPiece, NotchPiece)):
            sizes["thickness"] = p.thickness
            if isinstance(p, LeafPiece) and p.fillet > 0:
                sizes["fillet"] = p.fillet
                if p.x1 - p.x0 - 2 * p.fillet > 0:
                    sizes["flat leaf length (length - 2 fillet)"] = p.x1 - p.x0 - 2 * p.fillet
            for j in (i - 1, i + 1):
                if 0 <= j < len(ps) and isinstance(ps[j], BoxPiece):
                    for k, (box, leaf) in enumerate(zip(ps[j].end_extent(), p.end_extent())):
                        if box - leaf > 0:
                            sizes[f"block step along {'yz'[k]} (block height - t - 2 fillet)"] = box - leaf
    for name, value in sizes.items():
        if value < MIN_FEATURE_SIZE:
            raise ValueError(
                f"{name} = {value * 1e6:.3g} um is below the {MIN_FEATURE_SIZE * 1e6:.3g} um the CAD kernel "
                "resolves; make it zero (where allowed) or at least that large")


def _leaf_solid(p: LeafPiece) -> cq.Shape:
    """Leaf thin in y, extruded over z in [-hw, hw]; turned 90 deg about x when thin in z."""
    t, a, hw, x0, x1 = p.thickness, p.fillet, p.half_width, p.x0, p.x1
    h = t / 2 + a
    c = a / math.sqrt(2.0)
    wp = cq.Workplane("XY").workplane(offset=-hw).moveTo(x0, -h)
    if a > 0:
        flat = x1 - x0 - 2 * a > 0  # no flat part when the two fillets meet (length = 2 fillet)
        wp = wp.threePointArc((x0 + a - c, -h + c), (x0 + a, -t / 2))
        wp = wp.lineTo(x1 - a, -t / 2) if flat else wp
        wp = wp.threePointArc((x1 - a + c, -h + c), (x1, -h)).lineTo(x1, h)
        wp = wp.threePointArc((x1 - a + c, h - c), (x1 - a, t / 2))
        wp = wp.lineTo(x0 + a, t / 2) if flat else wp
        wp = wp.threePointArc((x0 + a - c, h - c), (x0, h))
    else:
        wp = wp.lineTo(x1, -h).lineTo(x1, h).lineTo(x0, h)
    solid = wp.close().extrude(2 * hw).val()
    if p.thin_axis == 2:
        solid = solid.rotate(cq.Vector(0, 0, 0), cq.Vector(1, 0, 0), 90.0)
    return solid


def _notch_solid(p: NotchPiece) -> cq.Shape:
    R, t, hw = p.radius, p.thickness, p.half_width
    h = t / 2 + R
    block = cq.Solid.makeBox(2 * R, 2 * h, 2 * hw, cq.Vector(p.x0, -h, -hw))
    for sign in (-1, 1):
        cutter = cq.Solid.makeCylinder(R, 4 * hw, cq.Vector(p.centre, sign * h, -2 * hw), cq.Vector(0, 0, 1))
        block = block.cut(cutter)
    return block


def _piece_solid(p: BoxPiece | LeafPiece | NotchPiece) -> cq.Shape:
    if isinstance(p, BoxPiece):
        return cq.Solid.makeBox(p.x1 - p.x0, 2 * p.half_y, 2 * p.half_z, cq.Vector(p.x0, -p.half_y, -p.half_z))
    if isinstance(p, LeafPiece):
        return _leaf_solid(p)
    return _notch_solid(p)


def _single_solid(shape: cq.Shape, what: str) -> cq.Solid:
    solids = shape.Solids()
    if len(solids) != 1 or not solids[0].isValid():
        raise RuntimeError(f"building the {what} gave {len(solids)} solid(s), valid={shape.isValid()}; "
                           "this is a bug in flexcal.geometry.solids, please report the parameters")
    return solids[0]


def _solid_from_pieces(params: Params, what: str) -> cq.Solid:
    _check_feature_sizes(params)
    parts = [_piece_solid(p) for p in pieces(params)]
    fused = parts[0].fuse(*parts[1:]).clean() if len(parts) > 1 else parts[0]
    return _single_solid(fused, what)


def hinge_solid(hinge: CircularNotchHinge | LeafHinge) -> Part:
    """Solid of one hinge in the hinge frame: x along the hinge from the fixed end face
    (x = -total_length/2) to the free end face (x = +total_length/2), thin along y, width
    along z, origin at the centre of the thin section. Reference points "fixed", "free"."""
    if not isinstance(hinge, (CircularNotchHinge, LeafHinge)):
        raise TypeError(f"hinge_solid takes a CircularNotchHinge or LeafHinge, got {type(hinge).__name__}")
    shape = _solid_from_pieces(hinge, type(hinge).__name__)
    return Part(shape=shape, params=hinge, reference_points=reference_points(hinge), end_planes=end_planes(hinge))


def chain_solid(chain: FlexureChain) -> Part:
    """Solid of one flexure chain in the chain frame: x from end A (x = 0) to end B
    (x = L), segments from ``chain.segments()``, leaf 1 thin in y, leaf 2 thin in z,
    blocks / connectors / strut of square ``section``. Reference points "A", "B"."""
    if not isinstance(chain, FlexureChain):
        raise TypeError(f"chain_solid takes a FlexureChain, got {type(chain).__name__}")
    shape = _solid_from_pieces(chain, "FlexureChain")
    return Part(shape=shape, params=chain, reference_points=reference_points(chain), end_planes=end_planes(chain))


def segment_solid(segment: ChainSegment) -> Part:
    """Solid of a chain segment (``ChainSegment``) in the chain frame, x from x_start
    (end "A") to x_end (end "B"); the prototype's superelements are condensed from it."""
    if not isinstance(segment, ChainSegment):
        raise TypeError(f"segment_solid takes a ChainSegment, got {type(segment).__name__}")
    shape = _solid_from_pieces(segment, "ChainSegment")
    return Part(shape=shape, params=segment, reference_points=reference_points(segment),
                end_planes=end_planes(segment))


def _location(rotation: np.ndarray, translation: np.ndarray) -> cq.Location:
    """Location mapping local coordinates x to rotation @ x + translation."""
    trsf = gp_Trsf()
    r, p = np.asarray(rotation, float), np.asarray(translation, float)
    trsf.SetValues(r[0, 0], r[0, 1], r[0, 2], p[0],
                   r[1, 0], r[1, 1], r[1, 2], p[1],
                   r[2, 0], r[2, 1], r[2, 2], p[2])
    return cq.Location(trsf)


@functools.lru_cache(maxsize=8)
def _cached_chain_shape(chain: FlexureChain) -> cq.Shape:
    return chain_solid(chain).shape


def mechanism_assembly(mech: MechanismParams) -> cq.Assembly:
    """The six chains placed in the mechanism frame (origin O_C, metres) for export and
    pictures: each chain's local frame maps to ``rotation @ x + point_a`` with the
    placement's ``rotation`` (columns = local axes). Parts are named "L1".."D3"; load
    chains are grey, driving chains orange. No base plate or payload frame is modelled."""
    assembly = cq.Assembly(name="mechanism")
    for placement in mech.chains:
        shape = _cached_chain_shape(placement.chain)
        colour = cq.Color(0.9, 0.5, 0.1) if placement.is_driving else cq.Color(0.6, 0.6, 0.65)
        assembly.add(shape, name=placement.name, color=colour,
                     loc=_location(placement.rotation, np.array(placement.point_a)))
    return assembly
