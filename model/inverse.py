"""Paper Eq. 8, inverse: target angles -> actuator inputs (Newton on the forward model).

For one parameter set, every point is solved for the inputs x (3) that make the forward
model's angles equal the target: Newton iterations from the linear model's inverse,
with the exact Jacobian of the forward map on its current piece (chain clearance statuses
held, parasitic term differentiated), and step halving when a step does not reduce the
residual (a kink between pieces). Converged when every point's angle error is
<= ``tol`` (1e-12 rad by default).

The map is not invertible where a driving chain floats in its gap with zero gain
(``mu = 1``: the nut follows the screw without moving the chain); there the Jacobian is
singular and ``NotInvertibleError`` names the point and chain.

Travel directions: with clearance the inverse is not unique over direction assignments
(a target can be reached approaching from either side, with different inputs), and
iterating "solve, then take the directions of the solution" need not settle. If not
given, the directions start from the linear model's inverse of the target sequence
(``travel_directions`` with moves below ``DIRECTION_MIN_MOVE`` = 1 um ignored, so that
small corrections to a held actuator do not flip its memory) and are replaced by the
solution's own up to ``DIRECTION_ROUNDS`` times; ``directions_consistent`` says whether
the returned inputs move the way the directions used say. Pass them for exact control.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .assembly import MechanismMatrices, mechanism_matrices
from .clearance import ConvergenceError
from .forward import ForwardResult, resolve_engine, solve_matrices
from .parameters import DRIVING, ParameterSpace, parameter_space
from .trajectory import travel_directions

__all__ = ["InverseResult", "inverse", "NotInvertibleError", "forward_jacobian"]

SINGULAR_GAIN = 1e-9  # relative |det J| below which the point counts as not invertible
MAX_STEP = 2e-3  # [m] largest Newton step of an input (the workspace needs ~1 mm)
LINE_SEARCH_HALVINGS = 30
DIRECTION_ROUNDS = 3  # solves with the directions of the previous solution before giving up on consistency
DIRECTION_MIN_MOVE = 1e-6  # [m] solved input changes below this do not reverse a travel direction


class NotInvertibleError(ValueError):
    """The forward map has no usable inverse at a point (a chain with zero gain in its gap)."""

    def __init__(self, message: str, point: int, chains: tuple[str, ...] = ()):
        super().__init__(message)
        self.point, self.chains = point, chains


@dataclass(frozen=True, kw_only=True)
class InverseResult:
    """inputs (n_p, 3) [m]; directions (n_p, 3) used; forward: the forward result at the
    inputs (candidate axis of length 1); residual (n_p, 3) [rad]; n_iterations (Newton);
    directions_consistent: the solved inputs' own travel directions (moves >= 1 um) equal
    the ones used (with clearance, other direction assignments can reach the same angles
    with other inputs, so this is reported rather than iterated)."""

    inputs: np.ndarray
    directions: np.ndarray
    forward: ForwardResult
    residual: np.ndarray
    n_iterations: int
    directions_consistent: bool


def forward_jacobian(matrices: MechanismMatrices, solution: dict, directions: np.ndarray, *,
                     parasitic: bool = True, clearance: bool = True, clearance_mode: str = "force_only") -> np.ndarray:
    """d(theta)/d(x) (n_p, 3, 3) [rad/m] of the forward map on its current piece, one candidate.

    solution: ``solve_matrices`` output for ``matrices`` (n_c = 1). With the statuses held,
    dr = R' dX (R' = dr/dX from r = -K_L |P X|^2), dC = E diag(mu/s) L_D (S dx + dr)
    (E = (I - B_FF)^-1 on the gap chains), du = S dx + dr + S dC, dX = H du; hence
    dX/dx = (I - H Bm)^-1 H A with A = S + S E Ds L_D S and Bm = R' + S E Ds L_D R'.
    """
    m = matrices
    pose = solution["pose"][0]  # (n_p, 6)
    n_p = pose.shape[0]
    h = m.input_gain[0]
    select = np.zeros((6, 3))
    select[3:, :] = np.eye(3)
    if parasitic:
        rows = m.parasitic_rows[0]  # (12, 6)
        lateral = pose @ rows.T  # (n_p, 12)
        k_l = m.parasitic_coefficient[0]
        r_prime = -2.0 * k_l[None, :, None] * (lateral[:, :6, None] * rows[None, :6, :]
                                                 + lateral[:, 6:, None] * rows[None, 6:, :])  # (n_p, 6, 6)
    else:
        r_prime = np.zeros((n_p, 6, 6))
    a_mat = np.broadcast_to(select, (n_p, 6, 3)).copy()
    b_mat = r_prime.copy()
    if clearance:
        c = solution["clearance"][0]
        d = np.ones((n_p, 3)) if clearance_mode == "force_only" else directions
        limit = m.clearance[0]
        lo, hi = np.minimum(d * limit, 0.0), np.maximum(d * limit, 0.0)
        free = (c > lo + 1e-15) & (c < hi - 1e-15) & (limit > 0)
        if np.any(free):
            coupling = (m.mu[0] / m.nut_stiffness[0])[:, None] * m.coupling[0, DRIVING, DRIVING] * (1.0 - np.eye(3))
            mask = free[:, :, None] & free[:, None, :]
            e_mat = np.linalg.inv(np.eye(3) - np.where(mask, coupling, 0.0)) * mask  # (n_p, 3, 3)
            ds_l = (m.mu[0] / m.nut_stiffness[0])[:, None] * m.load_gain[0, DRIVING, :]  # (3, 6)
            gain = e_mat @ ds_l  # dC / d(u without C), (n_p, 3, 6)
            a_mat[:, 3:, :] += gain[:, :, 3:]
            b_mat[:, 3:, :] += gain @ r_prime
    lhs = np.eye(6) - h @ b_mat
    dx_dinput = np.linalg.solve(lhs, h @ a_mat)
    return dx_dinput[:, 3:, :]


def _linear_inputs(matrices: MechanismMatrices, target: np.ndarray) -> np.ndarray:
    """Inverse of the linear model (no parasitic term, no clearance): (n_p, 3) [m]."""
    gain = matrices.input_gain[0, 3:, 3:]
    theta_g = matrices.gravity_pose[0, 3:]
    return np.linalg.solve(gain, (target - theta_g).T).T - matrices.initial_position[0]


def _line_search(matrices, target, directions, x, step, error, todo, options, tol, start=None):
    """x - scale * step with scale halved per point until the max angle error drops.

    At most MAX_STEP per input; points where the forward model fails halve too. Only
    ``todo`` points move. Returns (x, solution, residual, failed (n_p,) bool)."""
    scale = np.where(todo, np.minimum(1.0, MAX_STEP / np.maximum(np.max(np.abs(step), axis=1), 1e-300)), 0.0)
    keep_x, keep = start if start is not None else (x, None)
    for _ in range(LINE_SEARCH_HALVINGS):
        trial_x = np.where(todo[:, None], x - scale[:, None] * step, keep_x)
        try:
            trial = solve_matrices(matrices, trial_x, directions, **options)
        except ConvergenceError as error_at:
            if error_at.point is None:
                raise
            scale[error_at.point] *= 0.5
            continue
        trial_residual = trial["pose"][0, :, 3:] - target
        worse = todo & (np.max(np.abs(trial_residual), axis=1) > error) & (error > 10 * tol)
        if not np.any(worse):
            return trial_x, trial, trial_residual, worse
        scale[worse] *= 0.5
    return trial_x, trial, trial_residual, worse


def _newton(matrices, target, directions, x, options, tol, max_iter):
    n_p = target.shape[0]
    solution = solve_matrices(matrices, x, directions, **options)
    residual = solution["pose"][0, :, 3:] - target
    linear_gain = matrices.input_gain[0, 3:, 3:]
    reference_det = abs(np.linalg.det(linear_gain))
    iterations = 0
    for iterations in range(1, max_iter + 1):
        error = np.max(np.abs(residual), axis=1)
        todo = error > tol
        if not np.any(todo):
            return x, solution, residual, iterations - 1
        jac = forward_jacobian(matrices, solution, directions, parasitic=options["parasitic"],
                               clearance=options["clearance"], clearance_mode=options["clearance_mode"])
        det = np.abs(np.linalg.det(jac))
        singular = todo & (det < SINGULAR_GAIN * reference_det)
        if np.any(singular):
            point = int(np.argmax(singular))
            c = solution["clearance"][0, point]
            limit = matrices.clearance[0]
            gap = [f"D{i + 1}" for i in range(3) if 1e-15 < abs(c[i]) < limit[i] - 1e-15]
            raise NotInvertibleError(
                f"point {point}: the forward map is not invertible there (|det dtheta/dx| = {det[point]:.3g} "
                f"rad^3/m^3); chain(s) {', '.join(gap) or '(none in a gap)'} float in the clearance with "
                f"mu = {', '.join(f'{matrices.mu[0, int(g[1]) - 1]:.6g}' for g in gap) or '-'} (zero gain at mu = 1)",
                point=point, chains=tuple(gap))
        step = np.zeros_like(x)
        step[todo] = np.linalg.solve(jac[todo], residual[todo][..., None])[..., 0]
        trial_x, trial, trial_residual, failed = _line_search(matrices, target, directions, x, step, error, todo,
                                                              options, tol)
        if np.any(failed):  # the piece's Jacobian points the wrong way at a kink: use the linear model's
            fallback = np.zeros_like(x)
            fallback[failed] = np.linalg.solve(linear_gain, residual[failed].T).T
            trial_x, trial, trial_residual, failed = _line_search(matrices, target, directions, x, fallback, error,
                                                                  failed, options, tol, start=(trial_x, trial))
            if np.any(failed):
                point = int(np.argmax(failed))
                raise ConvergenceError("inverse line search failed (no step reduces the angle error; the target "
                                       "may lie beyond a clearance kink for these travel directions)", point=point)
        x, solution, residual = trial_x, trial, trial_residual
    point = int(np.argmax(np.max(np.abs(residual), axis=1)))
    raise ConvergenceError(f"inverse did not converge in {max_iter} Newton steps (angle error "
                           f"{np.max(np.abs(residual[point])):.3g} rad > tol = {tol:g} rad)", point=point)


def inverse(target_angles, directions=None, *, space_values=None, space: ParameterSpace | None = None,
            parasitic: bool = True, clearance: bool = True, clearance_mode: str = "force_only", tol: float = 1e-12,
            max_iter: int = 40, engine: str = "auto") -> InverseResult:
    """Actuator inputs (n_p, 3) [m] that give ``target_angles`` (n_p, 3) [rad] in order.

    space_values: (45,) [SI] the parameter set (nominal by default); directions (n_p, 3)
    of +-1 or None (from the linear inverse, see the module docstring). Other
    options as in ``forward``. Raises ``NotInvertibleError`` (a ``ValueError``) where a
    chain floats in its gap with zero gain, ``ConvergenceError`` if Newton fails.
    """
    space = space or parameter_space()
    values = space.nominal_full if space_values is None else np.asarray(space_values, dtype=float)
    if values.shape != (len(space.parameters),):
        raise ValueError(f"space_values must have shape ({len(space.parameters)},) for the inverse, got {values.shape}")
    target = np.atleast_2d(np.asarray(target_angles, dtype=float))
    if target.ndim != 2 or target.shape[1] != 3 or not np.all(np.isfinite(target)):
        raise ValueError(f"target angles must be finite with shape (n_points, 3) [rad], got {np.shape(target_angles)}")
    matrices = mechanism_matrices(values, space)
    options = dict(parasitic=parasitic, clearance=clearance, clearance_mode=clearance_mode,
                   engine=resolve_engine(engine, target.shape[0]), tol=min(1e-13, 0.1 * tol))
    x = _linear_inputs(matrices, target)
    if directions is None:
        d = travel_directions(x, min_move=DIRECTION_MIN_MOVE)
    else:
        d = np.broadcast_to(np.asarray(directions, dtype=float), target.shape).copy()
        if not np.all(np.abs(d) == 1.0):
            raise ValueError("directions must be +1 or -1 with the shape of the targets")
    iterations, rounds = 0, 1 if directions is not None else DIRECTION_ROUNDS
    for round_ in range(rounds):
        x_new, solution, residual, steps = _newton(matrices, target, d, x, options, tol, max_iter)
        iterations += steps
        own = travel_directions(x_new, min_move=DIRECTION_MIN_MOVE)
        consistent = bool(np.array_equal(own, d))
        x = x_new
        if consistent or round_ == rounds - 1:
            break
        d = own
    result = ForwardResult(pose=solution["pose"], axial_loads=solution["loads"], clearance=solution["clearance"],
                           release=solution["release"], parasitic=solution["parasitic"],
                           chain_states=solution["states"], point_class=solution["point_class"], inputs=x,
                           directions=d, n_iterations=solution["n_iterations"])
    return InverseResult(inputs=x, directions=d, forward=result, residual=residual, n_iterations=iterations,
                         directions_consistent=consistent)
