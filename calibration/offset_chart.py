"""The mount offsets in Cartesian components, the coordinates the estimator works in (issue #28).

The paper's sources give a chain's mount offset in polar coordinates, magnitude ``X.d`` in
[0, d_max] and direction ``X.phi`` in [0, 2 pi) (model/parameters.py). As coordinates of a fit
they have three defects, all measured (docs/calibration.md "Session 23"):

- at d = 0 the direction is undefined, and near it a linear bar on phi (or on a base
  combination holding it) does not describe the error (session 22: `paper` seed 2 designed,
  z 7.2 on L3.phi, 13.8 on its combination, for an estimate 2.1 standard errors off in
  Cartesian components);
- the box [0, 2 pi) cuts the circle: a direction cannot pass through 0;
- where an offset is poorly determined the objective has a minimum per direction: `paper`
  seed 6 standard (true L3.d 0.039 mm) fits to L2.phi 5.62, L3.phi 4.62 from the second-order
  start and to 1.79, 0.29 from the true values, fit 0.9923 against 0.9921 x the noise, and the
  leaf-thickness combinations holding them at z 9-14 against 2.4.

In Cartesian components of the offset (the model's own: chain end A moved by d (cos phi, sin phi)
in its local y-z plane) none of these exists: the origin is an ordinary point and the model is
smooth through it. So the estimator fits, groups base parameters and profiles in this chart, and
the reports give d and phi back with their bars by the delta method.

The chart's unit coordinates ``(X.dy, X.dz)`` in [0, 1]^2 (0.5, 0.5 is zero offset: the prior's
mid-range mean is the nominal, no offset) cover exactly the disc d <= d_max of the paper's
range, by the elliptical grid map of the square [-1, 1]^2 onto the unit disc (Fong, "Analytical
methods for squaring the disc", 2014: ``x = u sqrt(1 - v^2 / 2)``, ``y = v sqrt(1 - u^2 / 2)``,
with a closed-form inverse): smooth, one to one, the identity to first order at the origin
(offset / d_max = (u, v) + O(|u|^3)), so near zero offset the coordinates are the offset's
Cartesian components in units of d_max and the estimate can never leave the paper's range (a
report's values stay inside the bounds its readers check). The other sources' unit coordinates
are the space's own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["OffsetChart", "offset_chart"]

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True, kw_only=True, eq=False)
class OffsetChart:
    """names (n,): the estimation coordinates' names (``X.d``, ``X.phi`` become ``X.dy``,
    ``X.dz`` in place); pairs (k, 2): the (magnitude, direction) positions among the space's
    active sources, which are also the (dy, dz) positions among the chart's."""

    names: tuple[str, ...]
    pairs: np.ndarray

    def to_space(self, Y: np.ndarray) -> np.ndarray:
        """X (..., n) on the space's unit box from Y (..., n) on the chart's."""
        Y = np.asarray(Y, float)
        X = Y.copy()
        for i, j in self.pairs:
            x, y = _square_to_disc(2.0 * Y[..., i] - 1.0, 2.0 * Y[..., j] - 1.0)  # offset / d_max
            X[..., i] = np.hypot(x, y)
            X[..., j] = np.mod(np.arctan2(y, x), TWO_PI) / TWO_PI
        return X

    def from_space(self, X: np.ndarray) -> np.ndarray:
        """Y (..., n) on the chart's unit box from X (..., n) on the space's (a magnitude beyond
        the range is taken at its bound)."""
        X = np.asarray(X, float)
        Y = X.copy()
        for i, j in self.pairs:
            r, phi = np.clip(X[..., i], 0.0, 1.0), TWO_PI * X[..., j]
            u, v = _disc_to_square(r * np.cos(phi), r * np.sin(phi))
            Y[..., i], Y[..., j] = 0.5 + 0.5 * u, 0.5 + 0.5 * v
        return Y

    def jacobian(self, y: np.ndarray) -> np.ndarray:
        """dX/dY (n, n) at y (n,): the identity but for each pair's 2 x 2 block (infinite
        direction rows at zero offset, where the direction is undefined)."""
        y = np.asarray(y, float)
        J = np.eye(y.size)
        for i, j in self.pairs:
            u, v = 2.0 * y[i] - 1.0, 2.0 * y[j] - 1.0
            x, w = _square_to_disc(u, v)
            su, sv = np.sqrt(1.0 - u * u / 2.0), np.sqrt(1.0 - v * v / 2.0)
            # d(x, w)/d(u, v) of the elliptical grid map, times du/dY = dv/dY = 2
            dxy = 2.0 * np.array([[sv, -u * v / (2.0 * sv)], [-u * v / (2.0 * su), su]])
            r2 = x * x + w * w
            if r2 == 0.0:
                J[np.ix_([i, j], [i, j])] = np.inf
                continue
            r = np.sqrt(r2)
            polar = np.array([[x / r, w / r], [-w / (r2 * TWO_PI), x / (r2 * TWO_PI)]])  # d(r, phi / 2 pi)/d(x, w)
            J[np.ix_([i, j], [i, j])] = polar @ dxy
        return J

    def covariance_to_space(self, y: np.ndarray, covariance: np.ndarray) -> np.ndarray:
        """The covariance on the space's unit box of the chart's (n, n) at y, to first order
        (delta method); a direction at zero offset gets an infinite variance."""
        J = self.jacobian(y)
        finite = np.isfinite(J).all(axis=1)
        out = np.full_like(covariance, np.nan)
        Jf = J[finite]
        out[np.ix_(finite, finite)] = Jf @ covariance @ Jf.T
        for k in np.flatnonzero(~finite):
            out[k, k] = np.inf
        return out


def _square_to_disc(u, v):
    """The elliptical grid map [-1, 1]^2 -> unit disc (module doc)."""
    return u * np.sqrt(1.0 - v * v / 2.0), v * np.sqrt(1.0 - u * u / 2.0)


def _disc_to_square(x, y):
    """Its inverse, unit disc -> [-1, 1]^2 (Fong 2014, eq. for the elliptical grid map; the
    square roots' arguments are >= 0 on the disc, clipped for round-off)."""
    root = np.sqrt(2.0)
    p, q = 2.0 + x * x - y * y, 2.0 - x * x + y * y
    u = 0.5 * (np.sqrt(np.maximum(p + 2 * root * x, 0.0)) - np.sqrt(np.maximum(p - 2 * root * x, 0.0)))
    v = 0.5 * (np.sqrt(np.maximum(q + 2 * root * y, 0.0)) - np.sqrt(np.maximum(q - 2 * root * y, 0.0)))
    return u, v


def offset_chart(names) -> OffsetChart:
    """The chart of a space whose active sources are ``names``: every (X.d, X.phi) pair both
    active becomes (X.dy, X.dz); with none, the identity chart (pairs empty)."""
    names = list(names)
    index = {n: i for i, n in enumerate(names)}
    pairs = []
    for name in names:
        if name.endswith(".d") and name[:-2] + ".phi" in index:
            pairs.append((index[name], index[name[:-2] + ".phi"]))
    chart_names = list(names)
    for i, j in pairs:
        stem = names[i][:-2]
        chart_names[i], chart_names[j] = f"{stem}.dy", f"{stem}.dz"
    return OffsetChart(names=tuple(chart_names), pairs=np.array(pairs, int).reshape(-1, 2))
