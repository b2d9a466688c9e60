"""CadQuery solids of flexure hinges, flexure chains and the six-chain mechanism.

Frames as in ``flexcal.geometry.params``; lengths in metres inside the CadQuery shapes
too (``flexcal.geometry.export`` converts to mm when writing files). A solid is built
from the pieces of ``flexcal.geometry.exact`` (blocks and the profiles' compliant pieces),
the same decomposition the mesher uses for the exact surfaces, so CAD and analytic
description cannot drift apart silently (tests compare them).

Parameter validation happens in the parameter dataclasses; the only extra check here is
a minimum feature size that the CAD kernel can resolve.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import cadquery as cq
import numpy as np
from OCP.gp import gp_Trsf

from .exact import BoxPiece, Params, end_planes, pieces, reference_points
from .params import ChainSegment, FlexureChain, MechanismParams
from .profiles.protocol import HingeProfile

__all__ = ["Part", "hinge_solid", "chain_solid", "segment_solid", "mechanism_assembly", "location", "MIN_FEATURE_SIZE"]

#: Smallest dimension [m] the solids accept: 10x OpenCASCADE's confusion tolerance
#: (1e-7 model units = 0.1 um here), below which faces merge or booleans fail.
MIN_FEATURE_SIZE = 1e-6

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
        if not isinstance(p, BoxPiece):
            sizes.update(p.feature_sizes())
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


def _piece_solid(p) -> cq.Shape:
    if isinstance(p, BoxPiece):
        return cq.Solid.makeBox(p.x1 - p.x0, 2 * p.half_y, 2 * p.half_z, cq.Vector(p.x0, -p.half_y, -p.half_z))
    return p.solid()  # the profile's compliant piece builds its own


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


def hinge_solid(hinge: HingeProfile) -> Part:
    """Solid of one hinge in the hinge frame: x along the hinge from the fixed end face
    (x = -total_length/2) to the free end face (x = +total_length/2), thin along y, width
    along z, origin at the centre of the thin section. Reference points "fixed", "free"."""
    if not hasattr(hinge, "thin_piece"):
        raise TypeError(f"hinge_solid takes a hinge of flexcal.geometry.profiles (CircularNotchHinge, LeafHinge, "
                        f"...), got {type(hinge).__name__}")
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


def location(rotation: np.ndarray, translation: np.ndarray) -> cq.Location:
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
                     loc=location(placement.rotation, np.array(placement.point_a)))
    return assembly
