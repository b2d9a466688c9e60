"""The elliptical notch hinge: a block of height t + 2b with two half-elliptical cuts.

``EllipticalNotchHinge`` (the hinge, ``HingeProfile``), ``EllipticalNotchPiece`` (its
compliant piece, ``ThinPiece``) and ``EllipseCylinderPatch`` (the cut surface, an
elliptic cylinder along the width). Semi-axis a along the hinge (x), b across (y):
t(x) = t + 2b (1 - sqrt(1 - x^2/a^2)) over x in [-a, a]; a = b is the circular notch.
Lengths [m]. Smith et al. (1997), "Elliptical flexure hinges", Rev. Sci. Instrum. 68.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..patches import PlanePatch, axis_vector, side_cap
from ._rules import HingeRules
from .protocol import Dimension

__all__ = ["EllipticalNotchHinge", "EllipticalNotchPiece", "EllipseCylinderPatch", "HINGE"]

_BISECTIONS = 80  # halvings of the root's bracket: below double precision from any bracket we start with


def _box_excess(points: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.maximum(lower - points, 0.0) + np.maximum(points - upper, 0.0), axis=-1)


@dataclass(frozen=True, kw_only=True)
class EllipseCylinderPatch:
    """Elliptic cylinder along coordinate ``axis`` through ``centre``, semi-axis
    ``semi_axis_x`` along x and ``semi_axis_n`` along ``thin_axis``, bounded by the box
    [lower, upper]. The material lies outside (a concave notch), so the outward normal
    points towards the cylinder's axis."""

    name: str
    axis: int
    thin_axis: int
    centre: tuple[float, float, float]
    semi_axis_x: float
    semi_axis_n: float
    lower: tuple[float, float, float]
    upper: tuple[float, float, float]

    @property
    def plane_axes(self) -> tuple[int, int]:
        return 0, self.thin_axis

    def _closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """In-plane offsets (u along x, v along the thin axis) of the closest points on the
        ellipse to points (n, 3): Eberly's method ("Distance from a point to an ellipse",
        Geometric Tools 2013), the root of a monotone function found by bisection, exact to
        round-off for every point (Newton from an angle guess finds a far point for some
        points inside the ellipse)."""
        a, b = self.semi_axis_x, self.semi_axis_n
        qu = points[:, 0] - self.centre[0]
        qv = points[:, self.thin_axis] - self.centre[self.thin_axis]
        swap = a < b  # the method wants e0 >= e1
        e0, e1 = (b, a) if swap else (a, b)
        y0, y1 = (np.abs(qv), np.abs(qu)) if swap else (np.abs(qu), np.abs(qv))
        x0, x1 = np.empty_like(y0), np.empty_like(y1)
        # on the minor axis (y0 = 0): the co-vertex
        x0[:], x1[:] = 0.0, e1
        # on the major axis (y1 = 0): inside the evolute's cusp a point off the axis, else the vertex
        on_major = (y1 == 0) & (y0 > 0)
        cusp = on_major & (y0 < e0 - e1 * e1 / e0)
        x0[on_major], x1[on_major] = e0, 0.0
        x0[cusp] = e0 * e0 * y0[cusp] / (e0 * e0 - e1 * e1)
        x1[cusp] = e1 * np.sqrt(np.maximum(1.0 - (x0[cusp] / e0) ** 2, 0.0))
        general = (y0 > 0) & (y1 > 0)
        z0, z1 = y0[general] / e0, y1[general] / e1
        r0 = (e0 / e1) ** 2
        lo = z1 - 1.0
        hi = np.where(z0 * z0 + z1 * z1 < 1.0, 0.0, np.hypot(r0 * z0, z1) - 1.0)
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            f = (r0 * z0 / (mid + r0)) ** 2 + (z1 / (mid + 1.0)) ** 2 - 1.0
            lo, hi = np.where(f > 0, mid, lo), np.where(f > 0, hi, mid)
        root = 0.5 * (lo + hi)
        x0[general] = r0 * y0[general] / (root + r0)
        x1[general] = y1[general] / (root + 1.0)
        u, v = (x1, x0) if swap else (x0, x1)
        return np.copysign(u, qu), np.copysign(v, qv)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Closest points (n, 3) on the unbounded elliptic cylinder."""
        u, v = self._closest(points)
        out = np.array(points, float, copy=True)
        out[:, 0] = self.centre[0] + u
        out[:, self.thin_axis] = self.centre[self.thin_axis] + v
        return out

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        return np.linalg.norm(points - self.project(points), axis=-1)

    def distance(self, points: np.ndarray) -> np.ndarray:
        return np.hypot(self.surface_distance(points), _box_excess(points, np.array(self.lower), np.array(self.upper)))

    def normal(self, points: np.ndarray) -> np.ndarray:
        """Outward unit normals (n, 3) of the material at the closest points."""
        u, v = self._closest(points)
        out = np.zeros((len(points), 3))
        out[:, 0] = -u / self.semi_axis_x**2  # the gradient of (u/a)^2 + (v/b)^2, reversed
        out[:, self.thin_axis] = -v / self.semi_axis_n**2
        return out / np.linalg.norm(out, axis=-1, keepdims=True)

    def is_tangent_to(self, plane: PlanePatch, rtol: float = 1e-9) -> bool:
        if plane.axis not in self.plane_axes:
            return False
        semi = self.semi_axis_x if plane.axis == 0 else self.semi_axis_n
        return abs(abs(plane.value - self.centre[plane.axis]) - semi) <= rtol * semi

    def project_constrained(self, points: np.ndarray, fixed: set[int]) -> np.ndarray:
        """As ``CylinderPatch.project_constrained``: the free in-plane coordinate from the
        ellipse equation when the other is fixed by a plane."""
        free = [k for k in self.plane_axes if k not in fixed]
        if len(free) == 2:
            return self.project(points)
        out = np.array(points, float, copy=True)
        if len(free) == 1:
            k = free[0]
            other = self.thin_axis if k == 0 else 0
            semi_k, semi_o = ((self.semi_axis_x, self.semi_axis_n) if k == 0
                              else (self.semi_axis_n, self.semi_axis_x))
            root = semi_k * np.sqrt(np.maximum(1.0 - ((out[:, other] - self.centre[other]) / semi_o) ** 2, 0.0))
            side = np.where(out[:, k] >= self.centre[k], 1.0, -1.0)
            out[:, k] = self.centre[k] + side * root
        return out


@dataclass(frozen=True, kw_only=True)
class EllipticalNotchPiece:
    """Elliptical notch, x in [centre - a, centre + a], thin along y; semi-axes a (x), b (y)."""

    centre: float
    semi_axis_x: float
    semi_axis_y: float
    thickness: float
    half_width: float
    thin_axis: int = 1
    sizing_lines: ClassVar[int] = 41

    @property
    def x0(self) -> float:
        return self.centre - self.semi_axis_x

    @property
    def x1(self) -> float:
        return self.centre + self.semi_axis_x

    @property
    def width_axis(self) -> int:
        return 2

    def end_extent(self) -> tuple[float, float]:
        return self.thickness / 2 + self.semi_axis_y, self.half_width

    def local_thickness(self, x: np.ndarray) -> np.ndarray:
        """t(x) = t + 2b (1 - sqrt(1 - (x - centre)^2 / a^2)) [m], x (n,) [m] clamped to the piece."""
        u = np.clip((np.asarray(x, float) - self.centre) / self.semi_axis_x, -1.0, 1.0)
        return self.thickness + 2.0 * self.semi_axis_y * (1.0 - np.sqrt(np.maximum(1.0 - u * u, 0.0)))

    def volume(self) -> float:
        a, b, t = self.semi_axis_x, self.semi_axis_y, self.thickness
        # block 2a x (t + 2b) minus two half ellipses of area pi a b / 2
        return 2.0 * self.half_width * (2.0 * a * (t + 2.0 * b) - math.pi * a * b)

    def neck_half_length(self) -> float:
        """|x| where t(x) = 1.05 t: a sqrt(1 - (1 - 0.025 t/b)^2) (a when the cut is that shallow)."""
        q = 1.0 - 0.025 * self.thickness / self.semi_axis_y
        return self.semi_axis_x if q <= 0 else self.semi_axis_x * math.sqrt(1.0 - q * q)

    def curved_ranges(self) -> list[tuple[float, float, float]]:
        a, b = self.semi_axis_x, self.semi_axis_y
        return [(self.x0, self.x1, min(a * a / b, b * b / a))]  # smallest radius of curvature

    def feature_sizes(self) -> dict[str, float]:
        return {"thickness": self.thickness}

    def patches(self, label: str) -> list:
        """Side caps and the two elliptic notch cylinders (axis along the width)."""
        n, w, hw = self.thin_axis, self.width_axis, self.half_width
        b, t = self.semi_axis_y, self.thickness
        out = []
        for sign in (-1, 1):
            s = "+" if sign > 0 else "-"
            out.append(side_cap(self, label, sign))
            out.append(EllipseCylinderPatch(
                name=f"{label}:{s}{'xyz'[n]}notch", axis=w, thin_axis=n,
                centre=axis_vector({0: self.centre, n: sign * (t / 2 + b)}),
                semi_axis_x=self.semi_axis_x, semi_axis_n=b,
                lower=axis_vector({0: self.x0, n: min(sign * t / 2, sign * (t / 2 + b)), w: -hw}),
                upper=axis_vector({0: self.x1, n: max(sign * t / 2, sign * (t / 2 + b)), w: hw})))
        return out

    def solid(self):
        import cadquery as cq

        a, b, t, hw = self.semi_axis_x, self.semi_axis_y, self.thickness, self.half_width
        h = t / 2 + b
        block = cq.Solid.makeBox(2 * a, 2 * h, 2 * hw, cq.Vector(self.x0, -h, -hw))
        for sign in (-1, 1):
            cutter = (cq.Workplane("XY").workplane(offset=-2 * hw).center(self.centre, sign * h)
                      .ellipse(a, b).extrude(4 * hw).val())
            block = block.cut(cutter)
        return block


@dataclass(frozen=True, kw_only=True)
class EllipticalNotchHinge(HingeRules):
    """Elliptical notch hinge: a block of height t + 2b with two half-elliptical cuts.

    semi_axis_x a [m]: half the notch length (the hinge spans 2a in x); semi_axis_y b [m]:
    depth of each cut; thickness t [m] (minimum, at x = 0); width w [m] (along z);
    block_length [m]: rigid block on each side. a = b is the circular notch of radius a.
    """

    profile_name: ClassVar[str] = "elliptical"
    title: ClassVar[str] = "elliptical notch hinge (Smith et al. 1997)"
    dimensions: ClassVar[tuple[Dimension, ...]] = (
        Dimension(key="semi_axis_x", field="semi_axis_x", help="notch semi-axis a along the hinge [mm] (elliptical)"),
        Dimension(key="semi_axis_y", field="semi_axis_y", help="notch semi-axis b across, depth of each cut [mm] "
                                                               "(elliptical)"),
        Dimension(key="thickness", field="thickness", help="minimum thickness t [mm]"),
        Dimension(key="width", field="width", help="width b / w [mm]"),
    )
    refusal_notes: ClassVar[dict[str, str]] = {"thickness": "(a notch with t <= 0 cuts through the block)"}
    sweep_defaults_mm: ClassVar[dict[str, list[float]]] = {
        "semi_axis_x_mm": [10.0], "semi_axis_y_mm": [5.0], "thickness_mm": [0.5, 1.0, 1.5, 2.0],
        "width_mm": [10.0], "block_mm": [5.0]}

    semi_axis_x: float
    semi_axis_y: float
    thickness: float
    width: float
    block_length: float

    @property
    def height(self) -> float:
        """Block height t + 2b [m]."""
        return self.thickness + 2.0 * self.semi_axis_y

    @property
    def length(self) -> float:
        """Length of the notched part, 2a [m]."""
        return 2.0 * self.semi_axis_x

    def thin_piece(self) -> EllipticalNotchPiece:
        return EllipticalNotchPiece(centre=0.0, semi_axis_x=self.semi_axis_x, semi_axis_y=self.semi_axis_y,
                                    thickness=self.thickness, half_width=self.width / 2)

    @classmethod
    def default_block_mm(cls, dimensions_mm: dict[str, float]) -> float:
        return dimensions_mm["semi_axis_x"]

    def label(self) -> str:
        return (f"elliptical notch a {self.semi_axis_x * 1e3:g}, b {self.semi_axis_y * 1e3:g}, "
                f"t {self.thickness * 1e3:g}, w {self.width * 1e3:g} mm")

    def shape_ratio(self) -> float:
        """t/b [-] (the notch's t/R)."""
        return self.thickness / self.semi_axis_y


HINGE = EllipticalNotchHinge
