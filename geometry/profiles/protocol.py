"""What every hinge profile provides: ``HingeProfile`` (the hinge) and ``ThinPiece`` (its
compliant piece). Structural protocols: a profile module implements them, it does not
inherit from them. Hinge frame as in ``flexcal.geometry.params``; lengths [m].
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

__all__ = ["Dimension", "HingeProfile", "ThinPiece"]


@dataclass(frozen=True, kw_only=True)
class Dimension:
    """One dimension of a profile as the user gives it in mm.

    key: its name in reports and sweep tables ("radius" -> ``parameters_mm["radius"]``,
    sweep ``radius_mm``, command-line ``--radius-mm``); field: the hinge dataclass field
    it sets [m]; help: what it is, for ``--help``; default_mm: the value when not given
    (None: required); allow_zero: 0 is a valid value (a plain leaf's fillet).
    """

    key: str
    field: str
    help: str
    default_mm: float | None = None
    allow_zero: bool = False

    @property
    def option(self) -> str:
        """The command-line option, e.g. "--radius-mm"."""
        return "--" + self.key.replace("_", "-") + "-mm"


class ThinPiece(Protocol):
    """The compliant piece of a hinge or chain, x in [x0, x1] [m], thin along ``thin_axis``
    (1 = y, 2 = z) with minimum ``thickness`` [m], ``half_width`` [m] along ``width_axis``."""

    x0: float
    x1: float
    thin_axis: int
    thickness: float
    half_width: float
    #: grid lines per curved range of the fTetWild sizing grid (``fem.mesh_sizing``)
    sizing_lines: ClassVar[int]

    @property
    def width_axis(self) -> int: ...

    def end_extent(self) -> tuple[float, float]:
        """Half-extents (y, z) [m] of the cross-section at the piece's ends."""

    def local_thickness(self, x: np.ndarray) -> np.ndarray:
        """Thickness t(x) [m] along the thin axis at x (n,) [m], x clamped to the piece."""

    def volume(self) -> float:
        """Volume [m^3]."""

    def neck_half_length(self) -> float:
        """Half-length [m] about the middle where t(x) <= 1.05 t (where the neck is measured)."""

    def curved_ranges(self) -> list[tuple[float, float, float]]:
        """(x_start, x_end, smallest radius of curvature) [m] of each curved surface."""

    def feature_sizes(self) -> dict[str, float]:
        """Named dimensions [m] the CAD kernel must resolve (``solids.MIN_FEATURE_SIZE``)."""

    def patches(self, label: str) -> list[Any]:
        """The bounded analytic boundary surfaces (``flexcal.geometry.patches``), names
        prefixed "<label>:"; side caps named "<label>:+z"/"-z" (the width axis)."""

    def solid(self) -> Any:
        """The CadQuery solid of the piece (CadQuery is imported here, not at module load)."""


class HingeProfile(Protocol):
    """A single flexure hinge: a compliant piece between two rigid blocks of height
    ``height`` and length ``block_length`` [m], width ``width`` [m] along z."""

    profile_name: ClassVar[str]
    #: one line for ``--help`` and reports, e.g. "circular notch hinge"
    title: ClassVar[str]
    #: the dimensions the user gives, in the order reports list them (block last, apart)
    dimensions: ClassVar[tuple[Dimension, ...]]
    #: default ``[<profile name>]`` table of a sweep config (``validation/sweep/space.py``)
    sweep_defaults_mm: ClassVar[dict[str, list[float]]]

    thickness: float
    width: float
    block_length: float

    @property
    def height(self) -> float:
        """Block height [m]."""

    @property
    def length(self) -> float:
        """Length of the compliant part along x [m]."""

    @property
    def total_length(self) -> float:
        """Length of the whole part including both blocks [m]."""

    def thin_piece(self) -> ThinPiece:
        """The compliant piece, centred at x = 0, thin along y."""

    @classmethod
    def from_mm(cls, dimensions_mm: dict[str, float], block_mm: float) -> "HingeProfile":
        """The hinge from ``{Dimension.key: value [mm]}`` and the block length [mm]."""

    @classmethod
    def default_block_mm(cls, dimensions_mm: dict[str, float]) -> float:
        """Block length [mm] when the user gives none (half the compliant length)."""

    def label(self) -> str:
        """Short description with dimensions in mm, e.g. "notch R 5, t 1, b 10 mm"."""

    def shape_ratio(self) -> float:
        """The profile's shape figure (t/R for a notch, t/l for a leaf) [-]."""

    def chain_dimensions(self) -> dict[str, float] | None:
        """``FlexureChain`` fields that give every leaf of a chain this hinge's dimensions,
        or None when the mount's chains cannot take this profile (only leaves)."""
