"""Exact analytic description of hinge and chain solids: pieces, volume, thickness, ends.

Pure numpy, no CadQuery: the FEM mesher uses this to grade element sizes, to snap mesh
boundary nodes back onto the true surfaces and to measure how well a mesh reproduces
the part; ``flexcal.geometry.solids`` builds its CadQuery solids from the same pieces.

Every part here is a row of *pieces* along its local x axis (frames as in
``flexcal.geometry.params``):

- ``BoxPiece``: a rigid block or strut, x in [x0, x1], |y| <= half_y, |z| <= half_z;
- ``LeafPiece``: a corner-filleted leaf, thin along ``thin_axis`` (1 = y, 2 = z) with
  thickness t over x in [x0 + a, x1 - a], quarter-circle fillets of radius a at both
  ends (thickness t + 2a at x0 and x1), width 2 half_width along the other axis;
- ``NotchPiece``: a right-circular notch, x in [-R, R] about ``centre``, thickness
  t(x) = t + 2R - 2 sqrt(R^2 - (x - centre)^2) along y, width 2 half_width along z.

All lengths [m]. The boundary surfaces of the pieces are in ``flexcal.geometry.surfaces``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import numpy as np

from .params import ChainSegment, CircularNotchHinge, FlexureChain, LeafHinge

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

Params = Union[CircularNotchHinge, LeafHinge, FlexureChain, ChainSegment]


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


@dataclass(frozen=True, kw_only=True)
class LeafPiece:
    """Corner-filleted leaf, x in [x0, x1]; thin along ``thin_axis`` (1 = y, 2 = z).

    thickness t [m], fillet a [m] (0 = plain leaf), half_width [m] along the other axis.
    """

    x0: float
    x1: float
    thin_axis: int
    thickness: float
    fillet: float
    half_width: float

    @property
    def width_axis(self) -> int:
        return 3 - self.thin_axis

    def end_extent(self) -> tuple[float, float]:
        half_thin = self.thickness / 2 + self.fillet
        return (half_thin, self.half_width) if self.thin_axis == 1 else (self.half_width, half_thin)

    def local_thickness(self, x: np.ndarray) -> np.ndarray:
        """Thickness t(x) [m] along the thin axis at axial positions x (n,) [m] (x clamped to the piece)."""
        x = np.clip(np.asarray(x, float), self.x0, self.x1)
        a = self.fillet
        dx = np.maximum(np.maximum(self.x0 + a - x, x - (self.x1 - a)), 0.0)
        return self.thickness + 2.0 * (a - np.sqrt(np.maximum(a * a - dx * dx, 0.0)))


@dataclass(frozen=True, kw_only=True)
class NotchPiece:
    """Right-circular notch of radius R, x in [centre - R, centre + R], thin along y."""

    centre: float
    radius: float
    thickness: float
    half_width: float
    thin_axis: int = 1

    @property
    def x0(self) -> float:
        return self.centre - self.radius

    @property
    def x1(self) -> float:
        return self.centre + self.radius

    @property
    def width_axis(self) -> int:
        return 2

    def end_extent(self) -> tuple[float, float]:
        return self.thickness / 2 + self.radius, self.half_width

    def local_thickness(self, x: np.ndarray) -> np.ndarray:
        """t(x) = t + 2R - 2 sqrt(R^2 - (x - centre)^2) [m], x (n,) [m] clamped to the piece."""
        u = np.clip(np.asarray(x, float) - self.centre, -self.radius, self.radius)
        return self.thickness + 2.0 * (self.radius - np.sqrt(np.maximum(self.radius**2 - u * u, 0.0)))


Piece = Union[BoxPiece, LeafPiece, NotchPiece]


def pieces(params: Params) -> tuple[Piece, ...]:
    """The pieces of a hinge or chain from its fixed end / end A to its free end / end B."""
    if isinstance(params, CircularNotchHinge):
        h, R, b, e = params.height, params.radius, params.width, params.block_length
        return (
            BoxPiece(x0=-R - e, x1=-R, half_y=h / 2, half_z=b / 2),
            NotchPiece(centre=0.0, radius=R, thickness=params.thickness, half_width=b / 2),
            BoxPiece(x0=R, x1=R + e, half_y=h / 2, half_z=b / 2),
        )
    if isinstance(params, LeafHinge):
        h, l, w, e = params.height, params.length, params.width, params.block_length
        return (
            BoxPiece(x0=-l / 2 - e, x1=-l / 2, half_y=h / 2, half_z=w / 2),
            LeafPiece(x0=-l / 2, x1=l / 2, thin_axis=1, thickness=params.thickness, fillet=params.fillet,
                      half_width=w / 2),
            BoxPiece(x0=l / 2, x1=l / 2 + e, half_y=h / 2, half_z=w / 2),
        )
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
    raise TypeError(f"expected CircularNotchHinge, LeafHinge, FlexureChain or ChainSegment, got {type(params).__name__}")


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
    piece: LeafPiece | NotchPiece

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
        p = self.piece
        if isinstance(p, NotchPiece):
            return math.sqrt(0.05 * p.thickness * p.radius)
        flat = max(0.5 * (p.x1 - p.x0) - p.fillet, 0.0)
        # 2 (a - sqrt(a^2 - dx^2)) <= 0.05 t  <=>  dx <= sqrt(0.05 t a - (0.025 t)^2)
        # (a fillet shallower than 0.025 t stays below 1.05 t all the way)
        a, t = p.fillet, p.thickness
        return flat + (a if a <= 0.025 * t else math.sqrt(0.05 * t * a - (0.025 * t) ** 2))

    def thickness(self, x: np.ndarray) -> np.ndarray:
        return self.piece.local_thickness(x)


def thin_sections(params: Params) -> tuple[ThinSection, ...]:
    """The compliant pieces (leaves and notches) of a hinge or chain, from A to B."""
    return tuple(ThinSection(name=piece_label(params, i), piece=p)
                 for i, p in enumerate(pieces(params)) if not isinstance(p, BoxPiece))


def _piece_volume(piece: Piece) -> float:
    if isinstance(piece, BoxPiece):
        return (piece.x1 - piece.x0) * 4.0 * piece.half_y * piece.half_z
    if isinstance(piece, NotchPiece):
        R, t = piece.radius, piece.thickness
        # block 2R x (t + 2R) minus two half discs of radius R
        return 2.0 * piece.half_width * (2.0 * R * (t + 2.0 * R) - math.pi * R * R)
    length, t, a = piece.x1 - piece.x0, piece.thickness, piece.fillet
    # leaf l*t plus the four corners a^2 - pi a^2 / 4 outside the fillet arcs
    return 2.0 * piece.half_width * (length * t + 4.0 * a * a * (1.0 - math.pi / 4.0))


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
