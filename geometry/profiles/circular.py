"""The right-circular notch hinge: a block of height t + 2R with two semicircular cuts.

``CircularNotchHinge`` (the hinge, ``HingeProfile``) and ``NotchPiece`` (its compliant
piece, ``ThinPiece``): t(x) = t + 2R - 2 sqrt(R^2 - x^2) over x in [-R, R]. Lengths [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..patches import CylinderPatch, Patch, axis_vector, side_cap
from ._rules import HingeRules
from .protocol import Dimension

__all__ = ["CircularNotchHinge", "NotchPiece", "HINGE"]


@dataclass(frozen=True, kw_only=True)
class NotchPiece:
    """Right-circular notch of radius R, x in [centre - R, centre + R], thin along y."""

    centre: float
    radius: float
    thickness: float
    half_width: float
    thin_axis: int = 1
    sizing_lines: ClassVar[int] = 41

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

    def volume(self) -> float:
        R, t = self.radius, self.thickness
        # block 2R x (t + 2R) minus two half discs of radius R
        return 2.0 * self.half_width * (2.0 * R * (t + 2.0 * R) - math.pi * R * R)

    def neck_half_length(self) -> float:
        """|x| <= sqrt(0.05 t R): where t(x) <= 1.05 t (to first order in x^2 / R^2)."""
        return math.sqrt(0.05 * self.thickness * self.radius)

    def curved_ranges(self) -> list[tuple[float, float, float]]:
        return [(self.x0, self.x1, self.radius)]

    def feature_sizes(self) -> dict[str, float]:
        return {"thickness": self.thickness}

    def patches(self, label: str) -> list[Patch]:
        """Side caps and the two notch cylinders (axis along the width)."""
        n, w, hw = self.thin_axis, self.width_axis, self.half_width
        R, t = self.radius, self.thickness
        out: list[Patch] = []
        for sign in (-1, 1):
            s = "+" if sign > 0 else "-"
            out.append(side_cap(self, label, sign))
            out.append(CylinderPatch(name=f"{label}:{s}{'xyz'[n]}notch", axis=w, radius=R,
                                     centre=axis_vector({0: self.centre, n: sign * (t / 2 + R)}),
                                     lower=axis_vector({0: self.x0, n: min(sign * t / 2, sign * (t / 2 + R)), w: -hw}),
                                     upper=axis_vector({0: self.x1, n: max(sign * t / 2, sign * (t / 2 + R)), w: hw})))
        return out

    def solid(self):
        import cadquery as cq

        R, t, hw = self.radius, self.thickness, self.half_width
        h = t / 2 + R
        block = cq.Solid.makeBox(2 * R, 2 * h, 2 * hw, cq.Vector(self.x0, -h, -hw))
        for sign in (-1, 1):
            cutter = cq.Solid.makeCylinder(R, 4 * hw, cq.Vector(self.centre, sign * h, -2 * hw), cq.Vector(0, 0, 1))
            block = block.cut(cutter)
        return block


@dataclass(frozen=True, kw_only=True)
class CircularNotchHinge(HingeRules):
    """Right-circular notch hinge: a block of height t + 2R with two semicircular cuts.

    radius R [m], thickness t [m] (minimum, at x = 0), width b [m] (along z),
    block_length [m]: length of the rigid block on each side of the notch (the hinge
    spans 2R in x; the part is 2R + 2 block_length long). The free end is the face at
    x = R + block_length; the fixed end the face at x = -(R + block_length).
    """

    profile_name: ClassVar[str] = "circular"
    title: ClassVar[str] = "circular notch hinge"
    dimensions: ClassVar[tuple[Dimension, ...]] = (
        Dimension(key="radius", field="radius", help="notch radius R [mm] (circular)"),
        Dimension(key="thickness", field="thickness", help="minimum thickness t [mm]"),
        Dimension(key="width", field="width", help="width b / w [mm]"),
    )
    refusal_notes: ClassVar[dict[str, str]] = {"thickness": "(a notch with t <= 0 cuts through the block)"}
    sweep_defaults_mm: ClassVar[dict[str, list[float]]] = {
        "radius_mm": [5.0], "thickness_mm": [0.5, 1.0, 1.5, 2.0], "width_mm": [10.0], "block_mm": [5.0]}

    radius: float
    thickness: float
    width: float
    block_length: float

    @property
    def height(self) -> float:
        """Block height t + 2R [m]."""
        return self.thickness + 2.0 * self.radius

    @property
    def length(self) -> float:
        """Length of the compliant (notched) part, 2R [m]."""
        return 2.0 * self.radius

    def thin_piece(self) -> NotchPiece:
        return NotchPiece(centre=0.0, radius=self.radius, thickness=self.thickness, half_width=self.width / 2)

    @classmethod
    def default_block_mm(cls, dimensions_mm: dict[str, float]) -> float:
        return dimensions_mm["radius"]

    def label(self) -> str:
        return f"notch R {self.radius * 1e3:g}, t {self.thickness * 1e3:g}, b {self.width * 1e3:g} mm"

    def shape_ratio(self) -> float:
        """t/R [-]."""
        return self.thickness / self.radius


HINGE = CircularNotchHinge
