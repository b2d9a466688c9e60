"""Bounded analytic surfaces: the pieces of a part's boundary.

``PlanePatch`` (an axis-aligned plane) and ``CylinderPatch`` (a circular cylinder whose
axis is a coordinate axis), each bounded by a box; outward normals point out of the
material. A profile with another curved surface defines its patch class beside its piece
(``flexcal.geometry.profiles``) with the same methods: ``distance``, ``surface_distance``,
``normal``, ``project``, ``is_tangent_to(plane)`` and ``project_constrained(points,
fixed)``. Pure numpy, lengths [m], part frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

import numpy as np

__all__ = ["PlanePatch", "CylinderPatch", "Patch", "axis_vector", "side_cap"]


def _box_excess(points: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Distance (n,) [m] from points (n, 3) to the axis-aligned box [lower, upper]."""
    return np.linalg.norm(np.maximum(lower - points, 0.0) + np.maximum(points - upper, 0.0), axis=-1)


@dataclass(frozen=True, kw_only=True)
class PlanePatch:
    """Plane ``x[axis] = value`` bounded by the box [lower, upper]; outward normal
    ``sign * e_axis``. ``name`` says what it is (``"end:A"``, ``"leaf1:+y"``, ...)."""

    name: str
    axis: int
    value: float
    sign: int
    lower: tuple[float, float, float]
    upper: tuple[float, float, float]

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance (n,) [m] from points (n, 3) to the unbounded plane."""
        return np.abs(points[:, self.axis] - self.value)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distance (n,) [m] from points (n, 3) to the bounded patch (upper bound: plane and box distance combined)."""
        return np.hypot(self.surface_distance(points), _box_excess(points, np.array(self.lower), np.array(self.upper)))

    def normal(self, points: np.ndarray) -> np.ndarray:
        """Outward unit normals (n, 3)."""
        out = np.zeros((len(points), 3))
        out[:, self.axis] = self.sign
        return out

    def project(self, points: np.ndarray) -> np.ndarray:
        """Closest points (n, 3) on the unbounded plane."""
        out = np.array(points, float, copy=True)
        out[:, self.axis] = self.value
        return out


@dataclass(frozen=True, kw_only=True)
class CylinderPatch:
    """Circular cylinder of ``radius`` whose axis is parallel to coordinate ``axis`` and
    passes through ``centre`` (the coordinate along the axis is ignored), bounded by the
    box [lower, upper]. The material lies outside the cylinder (notches and fillets are
    concave), so the outward normal points towards the axis."""

    name: str
    axis: int
    centre: tuple[float, float, float]
    radius: float
    lower: tuple[float, float, float]
    upper: tuple[float, float, float]

    @property
    def plane_axes(self) -> tuple[int, int]:
        """The two coordinates (u, v) of the cross-section plane."""
        return tuple(i for i in range(3) if i != self.axis)  # type: ignore[return-value]

    def _radial(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u, v = self.plane_axes
        d = np.stack([points[:, u] - self.centre[u], points[:, v] - self.centre[v]], axis=-1)
        return d, np.linalg.norm(d, axis=-1)

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        return np.abs(self._radial(points)[1] - self.radius)

    def distance(self, points: np.ndarray) -> np.ndarray:
        return np.hypot(self.surface_distance(points), _box_excess(points, np.array(self.lower), np.array(self.upper)))

    def normal(self, points: np.ndarray) -> np.ndarray:
        d, r = self._radial(points)
        u, v = self.plane_axes
        out = np.zeros((len(points), 3))
        safe = np.where(r > 0, r, 1.0)
        out[:, u] = -d[:, 0] / safe
        out[:, v] = -d[:, 1] / safe
        return out

    def project(self, points: np.ndarray) -> np.ndarray:
        """Closest points (n, 3) on the unbounded cylinder (radial projection)."""
        d, r = self._radial(points)
        u, v = self.plane_axes
        safe = np.where(r > 0, r, 1.0)
        out = np.array(points, float, copy=True)
        out[:, u] = self.centre[u] + d[:, 0] * self.radius / safe
        out[:, v] = self.centre[v] + d[:, 1] * self.radius / safe
        return out


    def is_tangent_to(self, plane: "PlanePatch", rtol: float = 1e-9) -> bool:
        """True when ``plane`` touches this cylinder along a line (a flat leaf face running
        into its fillet): the line is no edge of the solid."""
        return plane.axis in self.plane_axes and \
            abs(abs(plane.value - self.centre[plane.axis]) - self.radius) <= rtol * self.radius

    def project_constrained(self, points: np.ndarray, fixed: set[int]) -> np.ndarray:
        """Points (n, 3) moved onto the unbounded cylinder keeping the coordinates in
        ``fixed`` (set by planes): radially with both in-plane coordinates free, along the
        free one with one fixed, unchanged with both fixed."""
        u, v = self.plane_axes
        free = [a for a in (u, v) if a not in fixed]
        if len(free) == 2:
            return self.project(points)
        out = np.array(points, float, copy=True)
        if len(free) == 1:
            a = free[0]
            b = v if a == u else u
            root = np.sqrt(np.maximum(self.radius**2 - (out[:, b] - self.centre[b]) ** 2, 0.0))
            side = np.where(out[:, a] >= self.centre[a], 1.0, -1.0)
            out[:, a] = self.centre[a] + side * root
        return out


Patch = Union[PlanePatch, CylinderPatch]


def axis_vector(axis_values: dict[int, float]) -> tuple[float, float, float]:
    out = [0.0, 0.0, 0.0]
    for axis, value in axis_values.items():
        out[axis] = value
    return tuple(out)  # type: ignore[return-value]


def side_cap(piece, label: str, sign: int) -> PlanePatch:
    """The plane bounding a thin piece across its width at ``sign`` * half_width (on its
    ``width_axis``), named "<label>:+z" / "<label>:-z" (or y)."""
    n, w = piece.thin_axis, piece.width_axis
    hw = piece.half_width
    half_end = piece.end_extent()[n - 1]
    return PlanePatch(name=f"{label}:{'+' if sign > 0 else '-'}{'xyz'[w]}", axis=w, value=sign * hw, sign=sign,
                      lower=axis_vector({0: piece.x0, n: -half_end, w: -hw}),
                      upper=axis_vector({0: piece.x1, n: half_end, w: hw}))
