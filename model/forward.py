"""Paper Eq. 8, forward: actuator inputs -> pose, chain loads, clearance states, point class.

For every candidate and point the axial A-end displacements are

    load chains:    u_i = r_i                       (Eq. 4-5 parasitic shortening)
    driving chains: u_i = x_i + x0_i + r_i + C_i    (input, initial position, Eq. 6-7 clearance)

with ``r_i = -K_Li (dy_i^2 + dz_i^2)`` from the lateral displacement of chain i's B-side
flexure centre under X_C, and ``X_C = X_g + H u`` (``assembly``). ``r`` depends on X_C and
``C`` on the loads, so (r, C) are found by fixed-point iteration on ``u`` with the
clearance solved exactly (``clearance``); it contracts by ~1e-2 per step (r ~ um, its
gain ~ |dy|/L_d). Converged when the update of ``u`` is <= ``tol`` (1e-13 m by default):
per point in the compiled engine (``kernel``), over all points in the numpy engine
(``solver``), with the clearance statuses consistent at the solution. (A stop on the
a-posteriori bound update * rho/(1 - rho) would save one step in five but was measured
to miss by up to 6e-12 m where the clearance switches faces, so it is not used.) Otherwise
``ConvergenceError`` names the candidate and point: divergence (|r| > 1 cm), no
convergence in ``max_iter`` steps, or no consistent clearance state. Never a silent NaN.

States per driving chain: 0 "engaged" (C = 0), 1 "gap" (0 < |C| < CL), 2 "far_flank"
(|C| = CL > 0), to ``STATE_TOLERANCE``. Point class: S2 if any driving chain has C != 0;
else S1 if all three driving chains are compressed (N < 0); else S3.
"""

from __future__ import annotations

import contextlib
import dataclasses
import sys
from dataclasses import dataclass

import numpy as np

from . import consistent, kernel, point_status, solver
from .assembly import MechanismMatrices, mechanism_matrices
from .clearance import ConvergenceError
from .parameters import DRIVING, ParameterSpace, parameter_space
from .second_order import second_order_pose
from .threads import thread_pool
from .trajectory import travel_directions

__all__ = ["ForwardResult", "forward", "solve_matrices", "ideal_pose", "ideal_angles", "ConvergenceError",
           "resolve_engine", "STATE_NAMES", "CLASS_NAMES", "STATE_TOLERANCE", "CLEARANCE_MODES", "ENGINES"]

STATE_NAMES = ("engaged", "gap", "far_flank")
CLASS_NAMES = {1: "S1", 2: "S2", 3: "S3"}
STATE_TOLERANCE = 1e-12  # [m] |C| below this is engaged, within this of CL is the far flank
CLEARANCE_MODES = ("directional", "force_only")
ENGINES = ("auto", "numba", "numpy")
AUTO_COMPILED_MIN = 200  # postures per call from which "auto" loads numba
# the consistent model (model/_numba_consistent.py): the pose's fixed point at given nut offsets
# contracts by ~1e-2 per step (< 20 steps from the previous point's pose); the offsets take
# Newton steps (2-4 where a nut is in its gap). 200 is a cap per equilibrium, not a typical count
CONSISTENT_MAX_ITER = 200
CONSISTENT_TOL = 1e-13  # [m, rad] offsets' update; the pose is iterated to 1e-2 of it
DIVERGENCE_LIMIT = 1e-2  # [m] a parasitic shortening this large (~1000x the workspace's) means it ran away


@dataclass(frozen=True, kw_only=True)
class ForwardResult:
    """Forward model output (n_c candidates, n_p points).

    pose (n_c, n_p, 6): X_C = [dx, dy, dz, theta_x, theta_y, theta_z] [m, rad] relative to
    the unloaded design pose; axial_loads (n_c, n_p, 6) [N], tension > 0, chains L1..D3;
    clearance (n_c, n_p, 3) C_A of D1..D3 [m] along each chain axis (towards B > 0);
    release (n_c, n_p, 3) fx_A [m] (Eq. 6, > 0: the load pulls the nut into the gap);
    parasitic (n_c, n_p, 6) r_A [m]; chain_states (n_c, n_p, 3) int8 indices into
    ``STATE_NAMES``; point_class (n_c, n_p) int8 in {1, 2, 3} (S1, S2, S3);
    inputs (n_p, 3) [m]; directions (n_p, 3) travel directions used; n_iterations.
    """

    pose: np.ndarray
    axial_loads: np.ndarray
    clearance: np.ndarray
    release: np.ndarray
    parasitic: np.ndarray
    chain_states: np.ndarray
    point_class: np.ndarray
    inputs: np.ndarray
    directions: np.ndarray
    n_iterations: int

    @property
    def angles(self) -> np.ndarray:
        """(n_c, n_p, 3) theta_x, theta_y, theta_z [rad]."""
        return self.pose[..., 3:]


def _check_points(inputs, directions) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(inputs, dtype=float)
    if x.ndim == 1:
        x = x[None, :]
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"inputs must have shape (n_points, 3) [m], got {x.shape}")
    if not np.all(np.isfinite(x)):
        point = int(np.argwhere(~np.isfinite(x))[0, 0])
        raise ValueError(f"inputs of point {point} are not finite: {x[point]}")
    if directions is None:
        d = travel_directions(x)
    else:
        d = np.asarray(directions, dtype=float)
        if d.ndim == 1:
            d = np.broadcast_to(d, x.shape)
        if d.shape != x.shape or not np.all(np.abs(d) == 1.0):
            raise ValueError(f"directions must be +1/-1 with the shape of the inputs {x.shape}, got {d.shape}")
    return x, np.array(d, dtype=float)


def _states_and_classes(clearance: np.ndarray, limit: np.ndarray, loads_driving: np.ndarray):
    """chain states (..., 3) int8 and point class (...) int8 from (..., 3) arrays."""
    size = np.abs(clearance)
    state = np.where(size <= STATE_TOLERANCE, 0, np.where((limit > 0) & (size >= limit - STATE_TOLERANCE), 2, 1))
    in_clearance = np.any(state > 0, axis=-1)
    compressed = np.all(loads_driving < 0, axis=-1)
    point_class = np.where(in_clearance, 2, np.where(compressed, 1, 3))
    return state.astype(np.int8), point_class.astype(np.int8)


def resolve_engine(engine: str, n_postures: int | None = None) -> str:
    """"auto" -> "numba" if it imports, else "numpy"; checks the name.

    With ``n_postures`` (candidates x points) below ``AUTO_COMPILED_MIN`` "auto" picks numpy
    unless numba is already loaded: a one-off small call (the command line) should not pay
    ~0.5 s of numba import.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine={engine!r} must be one of {ENGINES}")
    if engine == "auto":
        if n_postures is not None and n_postures < AUTO_COMPILED_MIN and "numba" not in sys.modules:
            return "numpy"
        return "numba" if kernel.available() else "numpy"
    if engine == "numba" and not kernel.available():
        raise ValueError("engine='numba' needs the numba package (pip install numba); use engine='numpy'")
    return engine


def _raise_for_codes(codes: np.ndarray, max_iter: int, tol: float, offset: int) -> None:
    bad = codes != point_status.OK
    if not np.any(bad):
        return
    cand, point = (int(i) for i in np.argwhere(bad)[0])
    reason = {point_status.NOT_CONVERGED: f"no convergence in {max_iter} iterations (tol = {tol:g} m)",
              point_status.DIVERGED: "the parasitic/clearance iteration diverges; the inputs are too large for the "
                               "small-deflection model",
              point_status.CLEARANCE_FAILED: "clearance solve found no consistent state"}[int(codes[cand, point])]
    raise ConvergenceError(reason, candidate=cand + offset, point=point)


def solve_matrices(matrices: MechanismMatrices, inputs: np.ndarray, directions: np.ndarray, *, parasitic: bool = True,
                   clearance: bool = True, clearance_mode: str = "force_only", tol: float = 1e-13,
                   max_iter: int = 60, engine: str = "auto", chunk_size: int = 64, n_threads: int = 1,
                   candidate_offset: int = 0) -> dict[str, np.ndarray]:
    """Eq. 8 at every point for precomputed per-candidate matrices.

    inputs, directions (n_p, 3) [m], [+-1]. Returns arrays in (n_c, n_p, k) layout: "pose" (6)
    [m, rad], "loads" (6) [N], "clearance" (3) [m], "release" (3) [m],
    "parasitic" (6) [m], "states" (3) int8, "point_class" () int8, and "n_iterations".
    """
    if clearance_mode not in CLEARANCE_MODES:
        raise ValueError(f"clearance_mode={clearance_mode!r} must be one of {CLEARANCE_MODES}")
    m = matrices
    play = bool(clearance and np.all(m.breakaway_band >= 0))
    if play and clearance_mode != "force_only":
        raise ValueError("the clearance's play state (ParameterSpace.breakaway_force) is written for "
                         "clearance_mode='force_only'; use that mode or breakaway_force=None")
    if play and resolve_engine(engine) != "numba":
        raise ValueError("the clearance's play state (ParameterSpace.breakaway_force) runs in the compiled engine "
                         "only (it carries each nut's offset from point to point); install numba or set "
                         "breakaway_force=None")
    d = np.ones_like(directions) if clearance_mode == "force_only" else directions
    if np.any(m.consistent):
        return _solve_consistent(m, inputs, clearance=clearance, clearance_mode=clearance_mode, parasitic=parasitic,
                                 tol=tol, max_iter=max_iter, engine=engine, n_threads=n_threads,
                                 candidate_offset=candidate_offset)
    options = dict(parasitic=parasitic, clearance=clearance, tol=tol, max_iter=max_iter, divergence=DIVERGENCE_LIMIT)
    if resolve_engine(engine) == "numba":
        out = kernel.solve_points_compiled(m, inputs, d, state_tolerance=STATE_TOLERANCE, n_threads=n_threads,
                                           **options)
        _raise_for_codes(out.pop("codes"), max_iter, tol, candidate_offset)
        out["n_iterations"] = int(out.pop("iterations").max(initial=0))
        return _with_second_order(m, out)
    parts = [solver.solve_points(_candidate_slice(m, s, s + chunk_size), inputs, d,
                                 candidate_offset=candidate_offset + s, **options)
             for s in range(0, m.n_candidates, max(1, int(chunk_size)))]
    u, c, r = (np.concatenate([p[k] for p in parts], axis=0) for k in range(3))
    pose = m.gravity_pose[:, None, :] + u @ np.swapaxes(m.input_gain, 1, 2)
    loads = m.gravity_loads[:, None, :] + u @ np.swapaxes(m.load_gain, 1, 2)
    s = m.nut_stiffness[:, None, :]
    release = d[None] * (loads[..., DRIVING] + s * c) / s
    limit = np.broadcast_to(m.clearance[:, None, :], c.shape)
    states, classes = _states_and_classes(c, limit, loads[..., DRIVING])
    return _with_second_order(m, {"pose": pose, "loads": loads, "clearance": c, "release": release, "parasitic": r,
                                  "states": states, "point_class": classes, "n_iterations": max(p[3] for p in parts)})


def _solve_consistent(m: MechanismMatrices, inputs, *, clearance, clearance_mode, parasitic, tol, max_iter, engine,
                      n_threads, candidate_offset) -> dict:
    """``model.consistent``'s compiled solve (force_only clearance, parasitic terms on)."""
    if not np.all(m.consistent):
        raise ValueError("candidates of one call must all use the consistent model or none")
    if clearance_mode != "force_only" or not parasitic or resolve_engine(engine) != "numba":
        raise ValueError("the consistent second-order model (ParameterSpace.chain_shortening) runs with "
                         "clearance_mode='force_only', parasitic=True and the compiled engine (numba)")
    out = consistent.solve_points_consistent(m, inputs, clearance=clearance, tol=max(tol, CONSISTENT_TOL),
                                             max_iter=CONSISTENT_MAX_ITER, divergence=DIVERGENCE_LIMIT,
                                             state_tolerance=STATE_TOLERANCE, n_threads=n_threads)
    _raise_for_codes(out.pop("codes"), CONSISTENT_MAX_ITER, max(tol, CONSISTENT_TOL), candidate_offset)
    out["n_iterations"] = int(out.pop("iterations").max(initial=0))
    return out


def _with_second_order(m: MechanismMatrices, out: dict) -> dict:
    """``out`` with its poses corrected by ``model.second_order`` where the candidates ask for it."""
    which = np.flatnonzero(m.second_order)
    if which.size:
        pose = out["pose"].copy()
        pose[which] = second_order_pose(_candidate_rows(m, which), pose[which], out["loads"][which])
        out["pose"] = pose
    return out


def _candidate_rows(matrices: MechanismMatrices, rows: np.ndarray) -> MechanismMatrices:
    if rows.size == matrices.n_candidates:
        return matrices
    return MechanismMatrices(**{f.name: getattr(matrices, f.name)[rows] for f in dataclasses.fields(matrices)})


def _candidate_slice(matrices: MechanismMatrices, start: int, stop: int) -> MechanismMatrices:
    return MechanismMatrices(**{f.name: getattr(matrices, f.name)[start:stop] for f in dataclasses.fields(matrices)})


def forward(space_values, inputs, directions=None, *, space: ParameterSpace | None = None, parasitic: bool = True,
            clearance: bool = True, clearance_mode: str = "force_only", tol: float = 1e-13, max_iter: int = 60,
            engine: str = "auto", n_threads: int = 1, chunk_size: int = 64) -> ForwardResult:
    """Forward model (Eq. 8) for a batch of parameter sets on an ordered input sequence.

    space_values (n_c, 45) or (45,) [SI] all parameters (``ParameterSpace.full_values``);
    inputs (n_p, 3) [m] actuator commands x_A1..x_A3 in trajectory order; directions
    (n_p, 3) of +-1, default ``travel_directions(inputs)``; space: the parameter space
    (mechanism) the values belong to, the reference one by default. parasitic / clearance:
    include Eq. 4-5 / Eq. 6-7; clearance_mode "directional" (d_i from the travel direction)
    or "force_only" (d_i = +1: only tension opens the gap). tol [m] on the fixed point.
    engine "auto" (numba if available), "numba" or "numpy" (reference); n_threads > 1 splits
    the candidates over that many threads: the compiled solve over numba threads (the consistent
    model's over Python threads, its set-up then on one) after the setup of the whole batch,
    whose bits then do not depend on n_threads (each candidate's solve is its own loop; the
    setup's paths and quadrature follow the batch it is given:
    ``chain.COMPILED_MIN_CHAINS``, ``hinge.gauss_node_count``); the numpy engine's setup and
    solve in Python threads over candidate blocks. chunk_size: candidates per numpy-engine
    block. The candidate axis is always present in the result.
    """
    space = space or parameter_space()
    values = np.atleast_2d(np.asarray(space_values, dtype=float))
    if values.ndim != 2:
        raise ValueError(f"space_values must have shape (n_candidates, 45) or (45,), got {np.shape(space_values)}")
    x, d = _check_points(inputs, directions)
    if (space.breakaway_force is not None or space.chain_shortening) and engine == "auto" and kernel.available():
        engine = "numba"  # the play state runs compiled only
    options = dict(parasitic=parasitic, clearance=clearance, clearance_mode=clearance_mode, tol=tol,
                   max_iter=max_iter, engine=resolve_engine(engine, values.shape[0] * x.shape[0]),
                   chunk_size=chunk_size)
    if n_threads <= 1 or values.shape[0] < 2:
        out = solve_matrices(mechanism_matrices(values, space), x, d, **options)
    elif options["engine"] == "numba":  # the whole batch's setup, then the compiled solve's threads
        # the consistent model solves on Python threads (model/threads.py): its set-up on one numba
        # thread, so that no OpenMP team spins beside them (docs/scale.md "Issue 26, session 38"),
        # its chain kernels split over the same threads (docs/model.md 10, "Session 42")
        with kernel.numba_threads(1) if space.chain_shortening else contextlib.nullcontext():
            matrices = mechanism_matrices(values, space, n_threads=n_threads)
        out = solve_matrices(matrices, x, d, n_threads=n_threads, **options)
    else:
        # the numpy engine: setup and solve in threads over candidate blocks
        bounds = np.linspace(0, values.shape[0], min(int(n_threads), values.shape[0]) + 1).astype(int)

        def block(span):
            matrices = mechanism_matrices(values[span[0]:span[1]], space, candidate_offset=int(span[0]))
            return solve_matrices(matrices, x, d, candidate_offset=int(span[0]), **options)

        parts = list(thread_pool().map(block, zip(bounds[:-1], bounds[1:])))
        out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k != "n_iterations"}
        out["n_iterations"] = max(p["n_iterations"] for p in parts)
    return ForwardResult(pose=out["pose"], axial_loads=out["loads"], clearance=out["clearance"],
                         release=out["release"], parasitic=out["parasitic"], chain_states=out["states"],
                         point_class=out["point_class"], inputs=x, directions=d, n_iterations=out["n_iterations"])


def ideal_pose(inputs, space: ParameterSpace | None = None) -> np.ndarray:
    """The small-deflection ("ideal", target) model: nominal parameters, no parasitic term, no
    clearance, with gravity. inputs (n_p, 3) [m] -> pose (n_p, 6) [m, rad]. The consistent
    second-order model's shortening (``chain_shortening``) is a parasitic term, so it is left out
    here too (its solve has no parasitic-free form)."""
    space = dataclasses.replace(space or parameter_space(), chain_shortening=(), shortening_slopes=())
    nominal = np.array([p.nominal for p in space.parameters])
    return forward(nominal, inputs, space=space, parasitic=False, clearance=False).pose[0]


def ideal_angles(inputs, space: ParameterSpace | None = None) -> np.ndarray:
    """Target angles (n_p, 3) [rad] of the ideal model (``ideal_pose``)."""
    return ideal_pose(inputs, space)[:, 3:]
