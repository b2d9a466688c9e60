"""Building blocks of the multi-subgroup PSO (``flexcal.calibration.pso``).

Pure functions on batched arrays in the normalized search space (the unit hypercube):
quasi-Monte-Carlo points, per-dimension velocity limits from sensitivity weights,
reflection at box walls, the choice and partition of isolated particles, and the
projection of global particles out of the subgroups' local domains.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "qmc_points",
    "velocity_limits",
    "reflect_into",
    "select_isolated",
    "partition_isolated",
    "inside_box",
    "project_out_of_boxes",
]


def qmc_points(n: int, n_dims: int, rng: np.random.Generator) -> np.ndarray:
    """(n, n_dims) scrambled Sobol points in [0, 1)^n_dims.

    A Sobol sequence is balanced only at powers of two and scipy warns otherwise, so
    ``random_base2(m)`` draws the 2^m >= n points and the first n are kept (a prefix of
    a (t, s)-sequence stays low-discrepancy; e.g. 300 of 512).
    """
    from scipy.stats import qmc

    if n <= 0:
        return np.empty((0, n_dims))
    m = max(0, int(np.ceil(np.log2(n))))
    try:
        engine = qmc.Sobol(d=n_dims, scramble=True, rng=rng)
    except TypeError:  # scipy < 1.15 names it ``seed``
        engine = qmc.Sobol(d=n_dims, scramble=True, seed=rng)
    return engine.random_base2(m)[:n]


def velocity_limits(n_dims: int, *, v_min: float, v_max: float, v_default: float,
                    sensitivity: np.ndarray | None = None) -> np.ndarray:
    """(n_dims,) maximum speed per dimension [fraction of the range per iteration].

    Without ``sensitivity`` every dimension gets ``v_default``. With it (n_dims,) >= 0,
    e.g. total Sobol indices, the limit falls linearly from ``v_max`` (least sensitive)
    to ``v_min`` (most sensitive): v = v_max - (v_max - v_min) (s - s_min) / (s_max - s_min).
    Equal sensitivities give ``v_default``.
    """
    if sensitivity is None:
        return np.full(n_dims, float(v_default))
    s = np.asarray(sensitivity, float)
    if s.shape != (n_dims,) or not np.all(np.isfinite(s)):
        raise ValueError(f"sensitivity must be {n_dims} finite numbers, got shape {s.shape}")
    s = np.clip(s, 0.0, None)
    span = s.max() - s.min()
    if span <= 0.0:
        return np.full(n_dims, float(v_default))
    return v_max - (v_max - v_min) * (s - s.min()) / span


def reflect_into(x: np.ndarray, v: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                 damping: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Reflect positions back into [lower, upper] and reverse the crossing velocity.

    x, v: (n, d); lower, upper: broadcastable to (n, d). A coordinate past a wall is
    mirrored at the wall (so particles are not parked on it) and its velocity
    component becomes ``-damping * v``. A coordinate still outside after one mirror
    (overshoot larger than the box) is clipped. Returns new (x, v).
    """
    x, v = x.copy(), v.copy()
    lower = np.broadcast_to(lower, x.shape)
    upper = np.broadcast_to(upper, x.shape)
    below, above = x < lower, x > upper
    x = np.where(below, 2.0 * lower - x, x)
    x = np.where(above, 2.0 * upper - x, x)
    v = np.where(below | above, -damping * v, v)
    return np.clip(x, lower, upper), v


def select_isolated(x: np.ndarray, candidates: np.ndarray, centre: np.ndarray, *, radius: float,
                    max_isolated: int) -> np.ndarray:
    """Indices (k,) of the particles to isolate, nearest first.

    x: (n, d) positions; candidates: (n,) bool, the global particles; centre: (d,) the
    global best [unit]. Particles within Euclidean distance ``radius`` of ``centre``,
    at most ``max_isolated`` of them.
    """
    index = np.flatnonzero(candidates)
    dist = np.linalg.norm(x[index] - centre, axis=1)
    order = np.argsort(dist, kind="stable")
    inside = order[dist[order] <= radius]
    return index[inside[:max_isolated]]


def partition_isolated(x: np.ndarray, f: np.ndarray, members: np.ndarray, max_size: int) -> list[np.ndarray]:
    """Split isolated particles into ceil(k / max_size) subgroups of balanced size.

    x: (n, d); f: (n,) current fitness; members: (k,) indices. Greedy: the best
    remaining particle seeds a subgroup and takes its nearest remaining neighbours.
    Returns a list of index arrays, best-seeded first; every size <= max_size.
    """
    members = np.asarray(members)
    if members.size == 0:
        return []
    n_groups = int(np.ceil(members.size / max_size))
    sizes = np.full(n_groups, members.size // n_groups)
    sizes[: members.size % n_groups] += 1
    remaining = list(members[np.argsort(f[members], kind="stable")])
    groups = []
    for size in sizes:
        seed = remaining.pop(0)
        if size > 1:
            rest = np.array(remaining)
            near = np.argsort(np.linalg.norm(x[rest] - x[seed], axis=1), kind="stable")[: size - 1]
            chosen = rest[near]
            remaining = [i for i in remaining if i not in set(chosen.tolist())]
            groups.append(np.concatenate([[seed], chosen]))
        else:
            groups.append(np.array([seed]))
    return groups


def inside_box(x: np.ndarray, centre: np.ndarray, half_width: float) -> np.ndarray:
    """(n,) bool: x (n, d) strictly inside the hypercube |x - centre| < half_width."""
    return np.all(np.abs(x - centre) < half_width, axis=-1)


def project_out_of_boxes(x: np.ndarray, v: np.ndarray, centres: np.ndarray, half_widths: np.ndarray,
                         *, margin: float = 1e-9) -> tuple[np.ndarray, np.ndarray, int]:
    """Move global particles out of every local domain (hypercube).

    x, v: (n, d) global particles; centres: (g, d); half_widths: (g,). A particle inside
    any box is moved along the one coordinate (and direction) that takes it out of the
    union of the boxes with the smallest displacement without leaving the unit box (a
    projection onto the nearest free face; overlapping boxes are crossed), and that
    velocity component is reversed. A particle that cannot leave along any single axis
    (boxes blocking every direction up to the walls) keeps its place with its velocity
    reversed. Returns (x, v, number of particles moved).
    """
    x, v = x.copy(), v.copy()
    centres = np.atleast_2d(centres)
    half_widths = np.asarray(half_widths, float)

    def containing(points):  # (k, g) bool
        return np.all(np.abs(points[:, None, :] - centres[None]) < half_widths[None, :, None], axis=-1)

    hit = np.flatnonzero(containing(x).any(axis=1))
    if hit.size == 0:
        return x, v, 0
    xh = x[hit]
    best_shift = np.full(hit.size, np.inf)
    best_dim = np.zeros(hit.size, int)
    best_value = np.zeros(hit.size)
    for dim in range(x.shape[1]):
        for side in (1.0, -1.0):
            y = xh[:, dim].copy()
            for _ in range(len(centres) + 1):
                points = xh.copy()
                points[:, dim] = y
                inside = containing(points)
                if not inside.any():
                    break
                faces = centres[:, dim] + side * (half_widths + margin)  # (g,)
                extreme = np.where(inside, faces[None, :], -np.inf * side)
                y = np.where(inside.any(axis=1), extreme.max(axis=1) if side > 0 else extreme.min(axis=1), y)
            points = xh.copy()
            points[:, dim] = y
            free = ~containing(points).any(axis=1) & (y >= 0.0) & (y <= 1.0)
            shift = np.where(free, np.abs(y - xh[:, dim]), np.inf)
            better = shift < best_shift
            best_shift[better], best_dim[better], best_value[better] = shift[better], dim, y[better]
    moved = np.isfinite(best_shift)
    rows = hit[moved]
    x[rows, best_dim[moved]] = best_value[moved]
    v[rows, best_dim[moved]] *= -1.0
    v[hit[~moved]] *= -1.0
    return x, v, int(moved.sum())
