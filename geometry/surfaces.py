"""The boundary of a hinge or chain solid as bounded analytic surfaces.

The boundary of every part built from the pieces of ``flexcal.geometry.exact`` is a
union of axis-aligned planes and circular cylinders whose axis is a coordinate axis
(``PlanePatch``, ``CylinderPatch``), each bounded by a box; outward normals point out of
the material. The mesher snaps boundary nodes onto them; the tests check that the CAD
solids lie on them. Pure numpy, lengths [m], part frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

import numpy as np

from .exact import BoxPiece, LeafPiece, NotchPiece, Params, end_names, piece_label, pieces

__all__ = ["PlanePatch", "CylinderPatch", "Patch", "boundary_patches"]


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


Patch = Union[PlanePatch, CylinderPatch]


def _vec(axis_values: dict[int, float]) -> tuple[float, float, float]:
    out = [0.0, 0.0, 0.0]
    for axis, value in axis_values.items():
        out[axis] = value
    return tuple(out)  # type: ignore[return-value]


def _box_patches(piece: BoxPiece, label: str) -> list[Patch]:
    hy, hz = piece.half_y, piece.half_z
    out: list[Patch] = []
    for sign in (-1, 1):
        out.append(PlanePatch(name=f"{label}:{'+' if sign > 0 else '-'}y", axis=1, value=sign * hy, sign=sign,
                              lower=(piece.x0, -hy, -hz), upper=(piece.x1, hy, hz)))
        out.append(PlanePatch(name=f"{label}:{'+' if sign > 0 else '-'}z", axis=2, value=sign * hz, sign=sign,
                              lower=(piece.x0, -hy, -hz), upper=(piece.x1, hy, hz)))
    return out


def _thin_piece_patches(piece: LeafPiece | NotchPiece, label: str) -> list[Patch]:
    """Lateral surfaces (flat leaf faces, fillet or notch cylinders) and the two side caps."""
    n, w = piece.thin_axis, piece.width_axis
    hw = piece.half_width
    out: list[Patch] = []
    half_end = piece.end_extent()[n - 1]
    for sign in (-1, 1):
        s = "+" if sign > 0 else "-"
        # side caps at width = +-hw
        out.append(PlanePatch(name=f"{label}:{s}{'xyz'[w]}", axis=w, value=sign * hw, sign=sign,
                              lower=_vec({0: piece.x0, n: -half_end, w: -hw}),
                              upper=_vec({0: piece.x1, n: half_end, w: hw})))
        if isinstance(piece, NotchPiece):
            R, t = piece.radius, piece.thickness
            out.append(CylinderPatch(name=f"{label}:{s}{'xyz'[n]}notch", axis=w, radius=R,
                                     centre=_vec({0: piece.centre, n: sign * (t / 2 + R)}),
                                     lower=_vec({0: piece.x0, n: min(sign * t / 2, sign * (t / 2 + R)), w: -hw}),
                                     upper=_vec({0: piece.x1, n: max(sign * t / 2, sign * (t / 2 + R)), w: hw})))
            continue
        t, a = piece.thickness, piece.fillet
        lo_n, hi_n = sorted((sign * t / 2, sign * (t / 2 + a)))
        out.append(PlanePatch(name=f"{label}:{s}{'xyz'[n]}", axis=n, value=sign * t / 2, sign=sign,
                              lower=_vec({0: piece.x0 + a, n: sign * t / 2, w: -hw}),
                              upper=_vec({0: piece.x1 - a, n: sign * t / 2, w: hw})))
        if a > 0:
            for end, (xc, xa, xb) in (("0", (piece.x0 + a, piece.x0, piece.x0 + a)),
                                      ("1", (piece.x1 - a, piece.x1 - a, piece.x1))):
                out.append(CylinderPatch(name=f"{label}:{s}{'xyz'[n]}fillet{end}", axis=w, radius=a,
                                         centre=_vec({0: xc, n: sign * (t / 2 + a)}),
                                         lower=_vec({0: xa, n: lo_n, w: -hw}),
                                         upper=_vec({0: xb, n: hi_n, w: hw})))
    return out


def boundary_patches(params: Params) -> tuple[Patch, ...]:
    """Every boundary surface of the part as bounded analytic patches, in the part's frame.

    The end faces come first and are named ``"end:<name>"`` with the names of
    ``end_planes`` ("fixed"/"free" for hinges, "A"/"B" for chains). Step faces where a
    block meets a narrower leaf are included (they may contain an interior region where
    the leaf is attached; that does no harm to classification by proximity).
    """
    ps = pieces(params)
    names = end_names(params)
    first, last = ps[0], ps[-1]
    hy0, hz0 = first.end_extent()
    hy1, hz1 = last.end_extent()
    out: list[Patch] = [
        PlanePatch(name=f"end:{names[0]}", axis=0, value=first.x0, sign=-1,
                   lower=(first.x0, -hy0, -hz0), upper=(first.x0, hy0, hz0)),
        PlanePatch(name=f"end:{names[1]}", axis=0, value=last.x1, sign=1,
                   lower=(last.x1, -hy1, -hz1), upper=(last.x1, hy1, hz1)),
    ]
    for i, piece in enumerate(ps):
        label = piece_label(params, i)
        if isinstance(piece, BoxPiece):
            out += _box_patches(piece, label)
            # step faces towards a thinner neighbour
            for j, x, sign in ((i - 1, piece.x0, -1), (i + 1, piece.x1, 1)):
                if 0 <= j < len(ps) and not isinstance(ps[j], BoxPiece):
                    ey, ez = ps[j].end_extent()
                    if ey < piece.half_y * (1 - 1e-12) or ez < piece.half_z * (1 - 1e-12):
                        out.append(PlanePatch(name=f"{label}:step{'-' if sign < 0 else '+'}x", axis=0, value=x,
                                              sign=sign, lower=(x, -piece.half_y, -piece.half_z),
                                              upper=(x, piece.half_y, piece.half_z)))
        else:
            out += _thin_piece_patches(piece, label)
    return tuple(out)
