"""Analytic benchmarks for the calibration algorithms, shipped with the code.

Sensitivity: the Ishigami function and the Sobol G-function, both with their exact
first-order and total Sobol indices computed here in closed form (not tabulated).

Optimization: batched test problems on the unit hypercube with known optima
(``OptimizationProblem``: sphere, Rosenbrock, Rastrigin, Ackley, all shifted so the
optimum is not the centre of the box) and a calibration-like nonlinear least-squares
problem (``curve_fit_problem``) with backlash, hysteresis, initial offsets, stiffness-like
gains and a few insensitive parameters, the stand-in for the mechanism model until the
lead wires the real one.

Every function is batch-first: inputs ``(n, d)``, outputs ``(n,)`` or ``(n, m)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = [
    "ishigami",
    "ishigami_indices",
    "ISHIGAMI_BOUNDS",
    "sobol_g",
    "sobol_g_indices",
    "OptimizationProblem",
    "sphere",
    "rosenbrock",
    "rastrigin",
    "ackley",
    "schwefel",
    "LeastSquaresProblem",
    "curve_fit_problem",
]

# ---------------------------------------------------------------- sensitivity


ISHIGAMI_BOUNDS = np.array([[-np.pi, np.pi]] * 3)


def ishigami(x: np.ndarray, a: float = 7.0, b: float = 0.1) -> np.ndarray:
    """Ishigami function ``sin x1 + a sin^2 x2 + b x3^4 sin x1``.

    x: (n, 3) in [-pi, pi]^3 (``ISHIGAMI_BOUNDS``). Returns (n,).
    """
    x = np.atleast_2d(np.asarray(x, float))
    return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])


def ishigami_indices(a: float = 7.0, b: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Exact (S1, ST), each (3,), of ``ishigami`` for uniform inputs on [-pi, pi]^3.

    Partial variances (Ishigami & Homma 1990; Sobol & Levitan 1999):
    V1 = (1 + b pi^4 / 5)^2 / 2, V2 = a^2 / 8, V13 = b^2 pi^8 (1/18 - 1/50), V3 = 0.
    """
    pi4 = np.pi**4
    v1 = 0.5 * (1.0 + b * pi4 / 5.0) ** 2
    v2 = a**2 / 8.0
    v13 = b**2 * pi4**2 * (1.0 / 18.0 - 1.0 / 50.0)
    v = v1 + v2 + v13
    s1 = np.array([v1, v2, 0.0]) / v
    st = np.array([v1 + v13, v2, v13]) / v
    return s1, st


def sobol_g(x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Sobol G-function ``prod_i (|4 x_i - 2| + a_i) / (1 + a_i)``.

    x: (n, d) in [0, 1]^d; a: (d,) >= 0 (small a_i = important input). Returns (n,).
    """
    x = np.atleast_2d(np.asarray(x, float))
    a = np.asarray(a, float)
    return np.prod((np.abs(4.0 * x - 2.0) + a) / (1.0 + a), axis=1)


def sobol_g_indices(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact (S1, ST), each (d,), of ``sobol_g`` for uniform inputs on [0, 1]^d.

    V_i = 1 / (3 (1 + a_i)^2), V = prod(1 + V_i) - 1,
    S_i = V_i / V, ST_i = V_i prod_{j != i} (1 + V_j) / V.
    """
    a = np.asarray(a, float)
    vi = 1.0 / (3.0 * (1.0 + a) ** 2)
    total = np.prod(1.0 + vi)
    v = total - 1.0
    return vi / v, vi * (total / (1.0 + vi)) / v


# ---------------------------------------------------------------- optimization


@dataclass(frozen=True, kw_only=True)
class OptimizationProblem:
    """A batched minimization problem on the unit hypercube with a known optimum.

    fitness: ``f(X (n, d) in [0, 1]^d) -> (n,)``; x_opt: (d,) the minimizer [unit box];
    f_opt: the minimum; name: for tables.
    """

    name: str
    n_dims: int
    fitness: Callable[[np.ndarray], np.ndarray]
    x_opt: np.ndarray
    f_opt: float

    def __post_init__(self) -> None:
        if self.x_opt.shape != (self.n_dims,):
            raise ValueError(f"x_opt has shape {self.x_opt.shape}, expected ({self.n_dims},)")


def _shifted_optimum(n_dims: int, rng) -> np.ndarray:
    """An optimum away from the centre and the walls: uniform in [0.2, 0.8]^d [unit]."""
    return np.random.default_rng(rng).uniform(0.2, 0.8, n_dims)


def _physical(x_unit: np.ndarray, x_opt: np.ndarray, half_width: float) -> np.ndarray:
    """Map the unit box to physical coordinates z with the optimum at z = 0."""
    return (np.atleast_2d(np.asarray(x_unit, float)) - x_opt) * (2.0 * half_width)


def sphere(n_dims: int, rng=0) -> OptimizationProblem:
    """Shifted sphere ``sum z^2``, z in [-5.12, 5.12]-sized box, minimum 0."""
    x_opt = _shifted_optimum(n_dims, rng)
    return OptimizationProblem(
        name=f"sphere-{n_dims}d", n_dims=n_dims, x_opt=x_opt, f_opt=0.0,
        fitness=lambda x: np.sum(_physical(x, x_opt, 5.12) ** 2, axis=1),
    )


def rosenbrock(n_dims: int, rng=0) -> OptimizationProblem:
    """Shifted Rosenbrock ``sum 100 (y_{i+1} - y_i^2)^2 + (1 - y_i)^2`` with y = z + 1,
    z in a box of width 4 (a narrow curved valley), minimum 0."""
    x_opt = _shifted_optimum(n_dims, rng)

    def fitness(x):
        y = _physical(x, x_opt, 2.0) + 1.0
        return np.sum(100.0 * (y[:, 1:] - y[:, :-1] ** 2) ** 2 + (1.0 - y[:, :-1]) ** 2, axis=1)

    return OptimizationProblem(name=f"rosenbrock-{n_dims}d", n_dims=n_dims, x_opt=x_opt, f_opt=0.0,
                               fitness=fitness)


def rastrigin(n_dims: int, rng=0) -> OptimizationProblem:
    """Shifted Rastrigin ``10 d + sum z^2 - 10 cos(2 pi z)``, z in a box of width 10.24
    (about 10^d local minima), minimum 0."""
    x_opt = _shifted_optimum(n_dims, rng)

    def fitness(x):
        z = _physical(x, x_opt, 5.12)
        return 10.0 * n_dims + np.sum(z**2 - 10.0 * np.cos(2.0 * np.pi * z), axis=1)

    return OptimizationProblem(name=f"rastrigin-{n_dims}d", n_dims=n_dims, x_opt=x_opt, f_opt=0.0,
                               fitness=fitness)


def ackley(n_dims: int, rng=0) -> OptimizationProblem:
    """Shifted Ackley, z in a box of width 65.5 (a nearly flat multimodal plateau with a
    narrow funnel), minimum 0."""
    x_opt = _shifted_optimum(n_dims, rng)

    def fitness(x):
        z = _physical(x, x_opt, 32.768)
        return (-20.0 * np.exp(-0.2 * np.sqrt(np.mean(z**2, axis=1)))
                - np.exp(np.mean(np.cos(2.0 * np.pi * z), axis=1)) + 20.0 + np.e)

    return OptimizationProblem(name=f"ackley-{n_dims}d", n_dims=n_dims, x_opt=x_opt, f_opt=0.0,
                               fitness=fitness)


def schwefel(n_dims: int) -> OptimizationProblem:
    """Schwefel 2.26 ``418.9829 d - sum z sin(sqrt|z|)`` on z in [-500, 500]^d: deceptive,
    the second-best minima lie far from the global one at z_i = 420.9687, minimum ~0."""
    z_opt = 420.968746
    x_opt = np.full(n_dims, (z_opt + 500.0) / 1000.0)

    def fitness(x):
        z = 1000.0 * np.atleast_2d(np.asarray(x, float)) - 500.0
        return 418.982887 * n_dims - np.sum(z * np.sin(np.sqrt(np.abs(z))), axis=1)

    return OptimizationProblem(name=f"schwefel-{n_dims}d", n_dims=n_dims, x_opt=x_opt,
                               f_opt=float(fitness(x_opt[None])[0]), fitness=fitness)


# ---------------------------------------------------------------- calibration-like


@dataclass(frozen=True, kw_only=True)
class LeastSquaresProblem:
    """A batched nonlinear least-squares calibration problem on the unit hypercube.

    residuals: ``r(X (n, d) in [0, 1]^d) -> (n, m)`` = (model - data) / noise scale
    [dimensionless]; fitness: ``f(X (n, d)) -> (n,)`` the paper's Eq. 13 shape, the mean
    over points of the per-point residual norm; x_true: (d,) the preset parameters
    [unit]; names: (d,); sensitive: (d,) bool, False for the deliberately weak ones;
    noise: standard deviation of the noise added to the data [residual units].
    """

    name: str
    residuals: Callable[[np.ndarray], np.ndarray]
    fitness: Callable[[np.ndarray], np.ndarray]
    x_true: np.ndarray
    names: tuple[str, ...]
    sensitive: np.ndarray
    noise: float

    @property
    def n_dims(self) -> int:
        return self.x_true.shape[0]


def _play(u: np.ndarray, half_gap: np.ndarray) -> np.ndarray:
    """Play (backlash) operator with direction memory, batched.

    u: (n_points,) input sequence; half_gap: (n, k) half clearance per channel.
    Returns (n, n_points, k): the output that follows u once u has taken up the gap,
    starting engaged on the positive side (y_0 = u_0 - half_gap).
    """
    y = np.empty(half_gap.shape[:1] + (u.shape[0],) + half_gap.shape[1:])
    prev = u[0] - half_gap
    for i, ui in enumerate(u):
        prev = np.clip(prev, ui - half_gap, ui + half_gap)
        y[:, i] = prev
    return y


def _features(e: np.ndarray) -> np.ndarray:
    """(n, points, 15) polynomial features of the engaged inputs e (n, points, 3):
    e_i, e_i^2, e_i e_k, e_i^3, e_i |e_i| (signatures of stiffness, parasitic and
    coupling effects)."""
    cross = np.stack([e[..., 0] * e[..., 1], e[..., 0] * e[..., 2], e[..., 1] * e[..., 2]], axis=-1)
    return np.concatenate([e, e**2, cross, e**3, e * np.abs(e)], axis=-1)


def curve_fit_problem(n_params: int = 20, *, n_insensitive: int = 3, n_points: int = 77,
                      noise: float = 0.0, screw_ripple: float = 0.0, screw_lead: float = 0.1,
                      rng=0) -> LeastSquaresProblem:
    """A calibration-like curve fit shaped like the mechanism's: three actuators driven
    one after another in reciprocal sweeps (0 -> +1 -> -1 -> 0, ``n_points`` points), three
    output angles, parameters of four kinds (all in the unit box; the model maps them):

    - 3 initial positions x0_i (offset of actuator i's input, +-0.15 of the stroke),
    - 3 clearances CL_i (backlash gap in [0, 0.25] of the stroke, with direction memory),
    - 3 hysteresis coefficients mu_i in [0.75, 1] (scale of the engaged stroke),
    - the rest: stiffness-like design parameters p_j in +-10 %, each adding its own
      signature (random weights on polynomial features of the engaged inputs, 0.05 of
      the angle scale) through the nonlinear factor (1 + p_j)^-3 - 1 (a hinge's t^3);
      the last ``n_insensitive`` are 1000x weaker (below a noise of 1).

    ``screw_ripple`` > 0 adds a known periodic screw error ``ripple sin(2 pi e_i / lead)``
    of each actuator's true position to every angle (angle-scale units; ``screw_lead``
    in strokes): its phase depends on x0, mu and CL, which makes the fit multimodal
    (about 0.3 / lead local minima along each x0), as a ball screw's per-revolution
    error does to a real calibration.

    Angles are theta = G (mu * play(u, CL) + x0) + sum_j g(p_j) F(e) W_j with a fixed
    gain matrix G. residuals are ``(model(x) - data) / 1e-3`` flattened over (points,
    angles) [noise units when noise = 1]. The preset x_true is drawn from ``rng`` in
    [0.15, 0.85]^d. n_params >= 10.
    """
    if n_params < 10:
        raise ValueError(f"n_params={n_params} must be >= 10 (9 actuator parameters + 1 design)")
    if not 0 <= n_insensitive <= n_params - 9:
        raise ValueError(f"n_insensitive={n_insensitive} must be in [0, {n_params - 9}]")
    if n_points < 13:
        raise ValueError(f"n_points={n_points} must be >= 13 (three legs of four points)")
    gen = np.random.default_rng(rng)
    n_design = n_params - 9
    legs = [len(part) for part in np.array_split(np.arange(n_points - 1), 3)]  # 77 -> 26, 25, 25
    u = np.zeros((n_points, 3))
    start = 1
    for k, n_leg in enumerate(legs):
        phase = np.linspace(0.0, 1.0, n_leg + 1)[1:]
        u[start:start + n_leg, k] = np.interp(phase, [0, 0.25, 0.75, 1.0], [0, 1, -1, 0])
        start += n_leg
    gain = np.array([[0.2, 0.1, 1.0], [1.0, 1.0, 0.1], [0.6, -0.6, 0.2]])  # (angle, actuator)
    strength = np.ones(n_design)
    if n_insensitive:
        strength[-n_insensitive:] = 1e-3
    weights = 0.05 * gen.standard_normal((n_design, 15, 3)) * strength[:, None, None]
    names = tuple([f"x0_{i + 1}" for i in range(3)] + [f"CL_{i + 1}" for i in range(3)]
                  + [f"mu_{i + 1}" for i in range(3)] + [f"p_{j + 1}" for j in range(n_design)])
    scale = 1e-3

    def model(x):
        x = np.atleast_2d(np.asarray(x, float))
        x0 = 0.3 * (x[:, 0:3] - 0.5)
        half_gap = 0.125 * x[:, 3:6]
        mu = 0.75 + 0.25 * x[:, 6:9]
        factor = (1.0 + 0.2 * (x[:, 9:] - 0.5)) ** -3 - 1.0  # (n, n_design), p in +-10 %
        engaged = np.stack([_play(u[:, i], half_gap[:, i:i + 1])[..., 0] for i in range(3)], axis=-1)
        e = mu[:, None, :] * engaged + x0[:, None, :]  # (n, points, actuators)
        theta = e @ gain.T
        theta += _features(e) @ np.tensordot(factor, weights, axes=1)
        if screw_ripple:
            theta += screw_ripple * np.sum(np.sin(2.0 * np.pi * e / screw_lead), axis=-1, keepdims=True)
        return theta  # (n, points, 3)

    x_true = gen.uniform(0.15, 0.85, n_params)
    data = model(x_true)[0] + noise * scale * gen.standard_normal((n_points, 3))

    def residuals(x):
        return ((model(x) - data) / scale).reshape(np.atleast_2d(x).shape[0], -1)

    def fitness(x):
        r = (model(x) - data) / scale
        return np.mean(np.linalg.norm(r, axis=-1), axis=-1)

    return LeastSquaresProblem(name=f"curve-fit-{n_params}d" + ("-ripple" if screw_ripple else ""),
                               residuals=residuals, fitness=fitness,
                               x_true=x_true, names=names, sensitive=np.arange(n_params) < n_params - n_insensitive,
                               noise=float(noise))
