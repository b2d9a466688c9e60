"""Exact analytic description of hinge and chain solids: pieces, volume, thickness, ends.

Pure numpy, no CadQuery: the FEM mesher uses this to grade element sizes, to snap mesh
boundary nodes back onto the true surfaces and to measure how well a mesh reproduces
the part; ``flexcal.geometry.solids`` builds its CadQuery solids from the same pieces.

Every part here is a row of *pieces* along its local x axis (frames as in
``flexcal.geometry.params``):

- ``BoxPiece``: a rigid block or strut, x in [x0, x1], |y| <= half_y, |z| <= half_z;
- a compliant piece (``ThinPiece``) of a hinge profile (``flexcal.geometry.profiles``):
  ``NotchPiece`` (right-circular notch), ``LeafPiece`` (corner-filleted leaf, thin along
  ``thin_axis`` 1 = y or 2 = z; every leaf of a chain too), ... Each gives its thickness
  t(x), volume, boundary surfaces and CAD solid itself.

A hinge is fixed block, its profile's piece, free block; a chain its segments.

All lengths [m]. The boundary surfaces of the pieces are in ``flexcal.geometry.surfaces``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

import numpy as np

from .params import ChainSegment, FlexureChain
from .profiles.circular import NotchPiece
from .profiles.leaf import LeafPiece
from .profiles.protocol import HingeProfile, ThinPiece

__all__ = [
    "BoxPiece",
    "LeafPiece",
    "NotchPiece",
    "ThinSection",
    "pieces",
    "piece_label",
    "thin_sections",
    "exact_volume",
    "end_names",
    "end_planes",
    "reference_points",
    "bounding_box",
]

Params = Union[HingeProfile, FlexureChain, ChainSegment]


@dataclass(frozen=True, kw_only=True)
class BoxPiece:
    """Rigid box x in [x0, x1], |y| <= half_y, |z| <= half_z [m]."""

    x0: float
    x1: float
    half_y: float
    half_z: float

    def end_extent(self) -> tuple[float, float]:
        """Half-extents (y, z) of the cross-section at the piece's ends [m]."""
        return self.half_y, self.half_z


Piece = Union[BoxPiece, ThinPiece]


def pieces(params: Params) -> tuple[Piece, ...]:
    """The pieces of a hinge or chain from its fixed end / end A to its free end / end B."""
    if isinstance(params, (FlexureChain, ChainSegment)):
        chain = params.chain if isinstance(params, ChainSegment) else params
        s = chain.section / 2
        out: list[Piece] = []
        for kind, x0, x1 in params.segments():
            if kind in ("leaf1", "leaf2"):
                axis = 1 if kind == "leaf1" else 2
                t = chain.thickness_1 if axis == 1 else chain.thickness_2
                out.append(LeafPiece(x0=x0, x1=x1, thin_axis=axis, thickness=t, fillet=chain.fillet,
                                     half_width=chain.width / 2))
            else:
                out.append(BoxPiece(x0=x0, x1=x1, half_y=s, half_z=s))
        return tuple(out)
    if not hasattr(params, "thin_piece"):
        raise TypeError(f"expected a hinge (flexcal.geometry.profiles), FlexureChain or ChainSegment, "
                        f"got {type(params).__name__}")
    # a hinge: fixed block, the profile's compliant piece (centred at x = 0), free block
    h, l, w, e = params.height, params.length, params.width, params.block_length
    return (
        BoxPiece(x0=-l / 2 - e, x1=-l / 2, half_y=h / 2, half_z=w / 2),
        params.thin_piece(),
        BoxPiece(x0=l / 2, x1=l / 2 + e, half_y=h / 2, half_z=w / 2),
    )


def piece_label(params: Params, index: int) -> str:
    """Name of piece ``index``: "<segment kind><index>" for chains ("leaf11"), else
    "block_fixed", "hinge", "block_free"."""
    if isinstance(params, (FlexureChain, ChainSegment)):
        return f"{params.segments()[index][0]}{index}"
    return ("block_fixed", "hinge", "block_free")[index]


# ----------------------------------------------------------------------------------------
# thin sections, volume, ends


@dataclass(frozen=True, kw_only=True)
class ThinSection:
    """A compliant piece: where it is, which way it is thin and how thick.

    x0, x1 [m]: axial range; thin_axis (1 = y, 2 = z); width_axis; half_width [m];
    neck_x [m]: axial position of the thinnest section; neck_thickness [m].
    ``thickness(x)`` gives t(x) [m] for x (n,) [m], clamped to [x0, x1].
    """

    name: str
    piece: ThinPiece

    @property
    def x0(self) -> float:
        return self.piece.x0

    @property
    def x1(self) -> float:
        return self.piece.x1

    @property
    def thin_axis(self) -> int:
        return self.piece.thin_axis

    @property
    def width_axis(self) -> int:
        return self.piece.width_axis

    @property
    def half_width(self) -> float:
        return self.piece.half_width

    @property
    def neck_x(self) -> float:
        return 0.5 * (self.piece.x0 + self.piece.x1)

    @property
    def neck_thickness(self) -> float:
        return self.piece.thickness

    @property
    def neck_half_length(self) -> float:
        """Half-length [m] of the region about ``neck_x`` where t(x) <= 1.05 t (the flat
        part of a leaf, or |x| <= sqrt(0.05 t R) for a notch): where the neck is measured."""
        return self.piece.neck_half_length()

    def thickness(self, x: np.ndarray) -> np.ndarray:
        return self.piece.local_thickness(x)


def thin_sections(params: Params) -> tuple[ThinSection, ...]:
    """The compliant pieces (leaves and notches) of a hinge or chain, from A to B."""
    return tuple(ThinSection(name=piece_label(params, i), piece=p)
                 for i, p in enumerate(pieces(params)) if not isinstance(p, BoxPiece))


def _piece_volume(piece: Piece) -> float:
    if isinstance(piece, BoxPiece):
        return (piece.x1 - piece.x0) * 4.0 * piece.half_y * piece.half_z
    return piece.volume()


def exact_volume(params: Params) -> float:
    """Volume of the solid [m^3] from its parameters (sum over pieces)."""
    return float(sum(_piece_volume(p) for p in pieces(params)))


def end_names(params: Params) -> tuple[str, str]:
    """Names of the two end faces: ("A", "B") for chains, ("fixed", "free") for hinges."""
    return ("A", "B") if isinstance(params, (FlexureChain, ChainSegment)) else ("fixed", "free")


def end_planes(params: Params) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The two end faces as ``name -> (point (3,) [m], outward unit normal (3,))``:
    "fixed"/"free" for hinges, "A"/"B" for chains. The point is the face centre."""
    ps = pieces(params)
    a, b = end_names(params)
    return {a: (np.array([ps[0].x0, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0])),
            b: (np.array([ps[-1].x1, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]))}


def reference_points(params: Params) -> dict[str, np.ndarray]:
    """End-face centres (3,) [m] by end name."""
    return {name: point for name, (point, _) in end_planes(params).items()}


def bounding_box(params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounding box (lower (3,), upper (3,)) [m] of the part."""
    ps = pieces(params)
    half = np.max([p.end_extent() for p in ps], axis=0)
    return np.array([ps[0].x0, -half[0], -half[1]]), np.array([ps[-1].x1, half[0], half[1]])
