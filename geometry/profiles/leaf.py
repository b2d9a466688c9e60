"""The corner-filleted leaf hinge (paper Fig. 5c), also every leaf of a flexure chain.

``LeafHinge`` (the hinge, ``HingeProfile``) and ``LeafPiece`` (its compliant piece,
``ThinPiece``): thickness t over the flat part, quarter-circle fillets of radius a at
both ends (thickness t + 2a at the ends). Lengths [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..checks import require
from ..patches import CylinderPatch, Patch, PlanePatch, axis_vector, side_cap
from ._rules import HingeRules
from .protocol import Dimension

__all__ = ["LeafHinge", "LeafPiece", "HINGE"]


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
    sizing_lines: ClassVar[int] = 9

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
        # u the distance to the nearer end: the arc's depth a - sqrt(a^2 - (a - u)^2) with a^2 - (a - u)^2
        # written u (2a - u), which is exactly 0 at an end (a^2 - dx^2 lost ~1e-21 m^2 there to
        # cancellation, and its root ~6e-11 m: the thickness at a fillet's end jumped with the fillet's
        # last bits, which shape derivatives on one connectivity difference; fem.condense_taylor)
        u = np.minimum(np.minimum(x - self.x0, self.x1 - x), a)
        return self.thickness + 2.0 * (a - np.sqrt(np.maximum(u * (2.0 * a - u), 0.0)))

    def volume(self) -> float:
        length, t, a = self.x1 - self.x0, self.thickness, self.fillet
        # leaf l*t plus the four corners a^2 - pi a^2 / 4 outside the fillet arcs
        return 2.0 * self.half_width * (length * t + 4.0 * a * a * (1.0 - math.pi / 4.0))

    def neck_half_length(self) -> float:
        """The flat part plus where the fillets stay below 1.05 t."""
        flat = max(0.5 * (self.x1 - self.x0) - self.fillet, 0.0)
        # 2 (a - sqrt(a^2 - dx^2)) <= 0.05 t  <=>  dx <= sqrt(0.05 t a - (0.025 t)^2)
        # (a fillet shallower than 0.025 t stays below 1.05 t all the way)
        a, t = self.fillet, self.thickness
        return flat + (a if a <= 0.025 * t else math.sqrt(0.05 * t * a - (0.025 * t) ** 2))

    def curved_ranges(self) -> list[tuple[float, float, float]]:
        if self.fillet > 0:
            return [(self.x0, self.x0 + self.fillet, self.fillet), (self.x1 - self.fillet, self.x1, self.fillet)]
        return []

    def feature_sizes(self) -> dict[str, float]:
        sizes = {"thickness": self.thickness}
        if self.fillet > 0:
            sizes["fillet"] = self.fillet
            if self.x1 - self.x0 - 2 * self.fillet > 0:
                sizes["flat leaf length (length - 2 fillet)"] = self.x1 - self.x0 - 2 * self.fillet
        return sizes

    def patches(self, label: str) -> list[Patch]:
        """Side caps, the two flat faces and the fillet cylinders (axis along the width)."""
        n, w, hw = self.thin_axis, self.width_axis, self.half_width
        t, a = self.thickness, self.fillet
        out: list[Patch] = []
        for sign in (-1, 1):
            s = "+" if sign > 0 else "-"
            out.append(side_cap(self, label, sign))
            lo_n, hi_n = sorted((sign * t / 2, sign * (t / 2 + a)))
            out.append(PlanePatch(name=f"{label}:{s}{'xyz'[n]}", axis=n, value=sign * t / 2, sign=sign,
                                  lower=axis_vector({0: self.x0 + a, n: sign * t / 2, w: -hw}),
                                  upper=axis_vector({0: self.x1 - a, n: sign * t / 2, w: hw})))
            if a > 0:
                for end, (xc, xa, xb) in (("0", (self.x0 + a, self.x0, self.x0 + a)),
                                          ("1", (self.x1 - a, self.x1 - a, self.x1))):
                    out.append(CylinderPatch(name=f"{label}:{s}{'xyz'[n]}fillet{end}", axis=w, radius=a,
                                             centre=axis_vector({0: xc, n: sign * (t / 2 + a)}),
                                             lower=axis_vector({0: xa, n: lo_n, w: -hw}),
                                             upper=axis_vector({0: xb, n: hi_n, w: hw})))
        return out

    def solid(self):
        """Leaf thin in y, extruded over z in [-hw, hw]; turned 90 deg about x when thin in z."""
        import cadquery as cq

        t, a, hw, x0, x1 = self.thickness, self.fillet, self.half_width, self.x0, self.x1
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
        if self.thin_axis == 2:
            solid = solid.rotate(cq.Vector(0, 0, 0), cq.Vector(1, 0, 0), 90.0)
        return solid


@dataclass(frozen=True, kw_only=True)
class LeafHinge(HingeRules):
    """Corner-filleted leaf hinge (paper Fig. 5c).

    length l [m]: segment length including both fillets; thickness t [m];
    width w [m] (along z); fillet radius a [m] (quarter circles at both ends, a = 0 is a
    plain leaf); block_height [m]: height of the blocks the leaf joins (>= t + 2a;
    ``None`` means t + 2a); block_length [m]: rigid block on each side.
    """

    profile_name: ClassVar[str] = "leaf"
    title: ClassVar[str] = "corner-filleted leaf hinge (paper Fig. 5c)"
    dimensions: ClassVar[tuple[Dimension, ...]] = (
        Dimension(key="length", field="length", help="segment length l including fillets [mm] (leaf)"),
        Dimension(key="thickness", field="thickness", help="minimum thickness t [mm]"),
        Dimension(key="width", field="width", help="width b / w [mm]"),
        Dimension(key="fillet", field="fillet", help="fillet radius a [mm] (leaf; default 0)", default_mm=0.0,
                  allow_zero=True),
    )
    sweep_defaults_mm: ClassVar[dict[str, list[float]]] = {
        "length_mm": [20.0], "thickness_mm": [4.0], "width_mm": [40.0], "fillet_mm": [6.0], "block_mm": [10.0]}

    length: float
    thickness: float
    width: float
    fillet: float
    block_length: float
    block_height: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        require(
            2.0 * self.fillet <= self.length,
            "fillet",
            self.fillet,
            f"<= length/2 = {self.length * 500:.6g} mm (both fillets must fit the segment)",
        )
        if self.block_height is not None:
            require(
                self.block_height >= self.thickness + 2.0 * self.fillet - 1e-12,
                "block_height",
                self.block_height,
                f">= t + 2a = {(self.thickness + 2 * self.fillet) * 1e3:.6g} mm",
            )

    @property
    def height(self) -> float:
        """Block height [m]."""
        return self.thickness + 2.0 * self.fillet if self.block_height is None else self.block_height

    def thin_piece(self) -> LeafPiece:
        l = self.length
        return LeafPiece(x0=-l / 2, x1=l / 2, thin_axis=1, thickness=self.thickness, fillet=self.fillet,
                         half_width=self.width / 2)

    @classmethod
    def default_block_mm(cls, dimensions_mm: dict[str, float]) -> float:
        return dimensions_mm["length"] / 2

    def label(self) -> str:
        return (f"leaf l {self.length * 1e3:g}, t {self.thickness * 1e3:g}, w {self.width * 1e3:g}, "
                f"a {self.fillet * 1e3:g} mm")

    def shape_ratio(self) -> float:
        """t/l [-]."""
        return self.thickness / self.length

    def chain_dimensions(self) -> dict[str, float]:
        return {"hinge_length": self.length, "width": self.width, "fillet": self.fillet,
                "thickness_1": self.thickness, "thickness_2": self.thickness}


HINGE = LeafHinge
