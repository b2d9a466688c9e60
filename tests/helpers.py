"""Test helpers shared by several test files (kept independent of the production
counters they check)."""

import numpy as np

from flexcal.fem.elements import EDGES, element_volumes


class Counting:
    """Batched function wrapper counting calls and rows, written separately from
    ``flexcal.calibration.polish.EvaluationCounter`` so tests of that counting are not
    checked against themselves."""

    def __init__(self, function):
        self.function, self.calls, self.rows = function, 0, 0

    def __call__(self, x):
        self.calls += 1
        self.rows += x.shape[0]
        return self.function(x)


def well_shaped_p2_tets(rng: np.random.Generator, n: int, curved: bool) -> np.ndarray:
    """n well-shaped P2 tets (n, 10, 3) [m] of size ~ 1 cm; curved ones have their
    mid-edge nodes moved by up to 5 % of their edge's length.

    Well-shaped means a mean-ratio quality 6*sqrt(2) V / l_rms^3 of at least 0.5
    (1 for the regular tet): random corners are redrawn until they pass, since a
    sliver would fold under the 5 % mid-node move (a real mesher rejects slivers too).
    """
    base = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    corners = np.empty((n, 4, 3))
    for k in range(n):
        while True:
            candidate = 0.01 * (base + 0.15 * rng.standard_normal((4, 3)))
            edges = candidate[EDGES[:, 1]] - candidate[EDGES[:, 0]]
            volume = np.linalg.det(candidate[1:] - candidate[0]) / 6.0
            rms_edge = np.sqrt((edges**2).sum(axis=1).mean())
            if 6.0 * np.sqrt(2.0) * volume / rms_edge**3 >= 0.5:
                corners[k] = candidate
                break
    mids = 0.5 * (corners[:, EDGES[:, 0]] + corners[:, EDGES[:, 1]])
    if curved:
        lengths = np.linalg.norm(corners[:, EDGES[:, 1]] - corners[:, EDGES[:, 0]], axis=-1)
        mids = mids + 0.05 * lengths[..., None] * rng.uniform(-1, 1, mids.shape)
    coords = np.concatenate([corners, mids], axis=1)
    assert (element_volumes(coords) > 0).all()
    return coords
