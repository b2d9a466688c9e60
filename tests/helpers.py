"""Test helpers shared by several test files (kept independent of the production
counters they check)."""

import numpy as np

from flexcal.fem.elements import EDGES, REFERENCE_NODES, TET_14POINT, element_volumes, jacobians, shape_gradients


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

    Well-shaped: a mean-ratio quality 6 sqrt(2) V / l_rms^3 of at least 0.5 (1 for the
    regular tet) and, if curved, det J of the quadratic map at the ten nodes and the 14
    quadrature points at least a quarter of the straight tet's. Draws that fail are
    redrawn: a sliver, or a curved tet folding at a corner node, is what a mesher rejects
    too, and the element code rightly refuses it (tested separately).
    """
    base = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    checked_points = np.vstack([REFERENCE_NODES, TET_14POINT.points])
    out = np.empty((n, 10, 3))
    k = 0
    while k < n:
        corners = 0.01 * (base + 0.15 * rng.standard_normal((4, 3)))
        edges = corners[EDGES[:, 1]] - corners[EDGES[:, 0]]
        straight_det = np.linalg.det(corners[1:] - corners[0])  # 6 V
        rms_edge = np.sqrt((edges**2).sum(axis=1).mean())
        if np.sqrt(2.0) * straight_det / rms_edge**3 < 0.5:  # 6 sqrt(2) V / l_rms^3
            continue
        mids = 0.5 * (corners[EDGES[:, 0]] + corners[EDGES[:, 1]])
        if curved:
            lengths = np.linalg.norm(edges, axis=1)
            mids = mids + 0.05 * lengths[:, None] * rng.uniform(-1, 1, mids.shape)
        coords = np.concatenate([corners, mids])
        det = np.linalg.det(jacobians(coords[None], shape_gradients(checked_points)))
        if det.min() < 0.25 * straight_det:
            continue
        out[k] = coords
        k += 1
    assert (element_volumes(out) > 0).all()
    return out


def quad_hinge_entries(thickness, free_end, breaks, width, material):
    """A hinge's compliance entries as the Euler-Bernoulli/Timoshenko integrals of
    model/hinge.py's docstring over the thickness profile ``thickness(x)`` [m], by adaptive
    quad on the intervals between ``breaks`` [m] (the profile's kinks and the points where
    the torsion formula switches sides, t(x) = width), moments taken about ``free_end`` [m].
    Written here from the formulas, independently of model/hinge.py's quadrature."""
    from scipy.integrate import quad

    from flexcal.model import hinge

    e, g = material.youngs_modulus, material.shear_modulus
    kappa = float(hinge.shear_coefficient(material.poisson_ratio))
    w = width

    def integral(f):
        return sum(quad(f, lo, hi, epsabs=0.0, epsrel=1e-13, limit=200)[0] for lo, hi in zip(breaks[:-1], breaks[1:]))

    def xi(x):  # distance from the free end
        return free_end - x

    return {
        "ux_Fx": integral(lambda x: 1 / (e * w * thickness(x))),
        "uy_Fy": integral(lambda x: 12 * xi(x) ** 2 / (e * w * thickness(x) ** 3) + 1 / (kappa * g * w * thickness(x))),
        "uy_Mz": integral(lambda x: 12 * xi(x) / (e * w * thickness(x) ** 3)),
        "rz_Mz": integral(lambda x: 12 / (e * w * thickness(x) ** 3)),
        "uz_Fz": integral(lambda x: 12 * xi(x) ** 2 / (e * w**3 * thickness(x)) + 1 / (kappa * g * w * thickness(x))),
        "uz_My": -integral(lambda x: 12 * xi(x) / (e * w**3 * thickness(x))),
        "ry_My": integral(lambda x: 12 / (e * w**3 * thickness(x))),
        "rx_Mx": integral(lambda x: 1 / (g * float(hinge.torsion_constant(thickness(x), w)))),
    }


def rigid_energy_and_stretch_volume_error(K, nodes: np.ndarray, volume: float, material) -> tuple[float, float]:
    """(largest energy v^T K v of the four rigid motions (three rotations about the axes, a
    translation) over the sum of its terms' magnitudes |v|^T |K| |v| [-], the relative error
    of the volume the uniform stretch u = (x, 0, 0) sees: v^T K v / ((lambda + 2 mu) volume) - 1
    [-]) for a stiffness K (3 n, 3 n) [SI] on nodes (n, 3) [m] of a part of ``volume`` [m^3]."""
    E, nu = material.youngs_modulus, material.poisson_ratio
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    X, Y, Z = nodes.T
    zero = np.zeros_like(X)
    energies = []
    for u in (np.c_[-Y, X, zero], np.c_[zero, -Z, Y], np.c_[Z, zero, -X], np.c_[np.ones_like(X), zero, zero]):
        v = u.ravel()
        energies.append(abs(v @ (K @ v)) / (np.abs(v) @ (abs(K) @ np.abs(v))))
    stretch = np.c_[X, zero, zero].ravel()
    return max(energies), stretch @ (K @ stretch) / ((lam + 2 * mu) * volume) - 1.0
