"""The virtual prototype: the mechanism's "truth" from segment superelements, exact
kinematics, a physical actuator transmission and gravity (docs/prototype.md).

``build_prototype(mechanism, transmissions, provider)`` cuts every chain into five
segments (``flexcal.validation.prototype.segments``), asks the stiffness provider for each, and
sets up the bodies of the equilibrium problem (``flexcal.validation.prototype.equilibrium``):

- body 0: the payload frame, pose at O_C, 6 DOF (design pose: identity);
- bodies 1..24: the four interior section nodes of each chain (L1..L3, D1..D3), 6 DOF;
- bodies 25..27: the nuts of D1..D3, 1 DOF (axial, along the chain), tied by the
  contact spring ``actuator_stiffness`` to the anchor ``s_i + g_i`` (``transmission``);
- body 28: ground (the load chains' base ends A).
Node A of a chain sits on ground or on its nut, node B on the frame at ``point_b``.
That is 6 + 24 * 6 + 3 = 153 unknowns.

``simulate(prototype, inputs)`` walks a trajectory (n_points, 3) [m] of commanded
actuator displacements: per point it applies the effects' hooks, then solves mechanism
equilibrium (Newton) and the nut offsets (outer fixed point, ``SolverSettings``)
together, warm-started from the previous point.

Angles are the rotation vector of the frame's rotation R_f (= log R_f, design pose
R_f = I), components (theta_x, theta_y, theta_z) [rad] in the mechanism frame; the pose
is (O_C displacement [m], rotation vector [rad]). See docs/conventions.md for what is
measured.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import scipy.linalg

from flexcal.geometry.params import MechanismParams
from flexcal.model.trajectory import next_direction

from ..blas_threads import single_blas_thread
from .fixed_point import anderson_step
from .kinematics import pose, so3_log, translation_pose
from ..effects.hooks import EffectContext, PointConditions, PointResult, effect_record, room_temperature
from .equilibrium import (Assembly, Loads, NonConvergenceError, SolverSettings, build_assembly, solve_equilibrium)
from .superelement import CoupledStiffness
from .segments import StiffnessProvider, end_stiffness, prepare_chains, rigid_mode_defect, section_nodes
from .transmission import ActuatorTransmission, nut_offset, point_class

__all__ = [
    "Prototype",
    "PrototypeRun",
    "build_prototype",
    "prepare_prototype",
    "apply_mount_offsets",
    "simulate",
    "frame_stiffness",
    "stiffness_congruence",
    "tied_chain_stiffness",
    "FRAME_BODY",
    "NUT_BODIES",
]

N_CHAINS, N_SEGMENTS = 6, 5
FRAME_BODY = 0
INTERIOR_BODIES = np.arange(1, 25).reshape(6, 4)  # [chain, interior node]
NUT_BODIES = (25, 26, 27)
GROUND_BODY = 28
# A provider's 12 x 12 must vanish on rigid motions to this relative level
# (segments.rigid_mode_defect); exact condensations give ~1e-12, so 1e-6 only rejects
# matrices that are not free-free segment stiffnesses at all (wrong frame or DOF order).
RIGID_DEFECT_LIMIT = 1e-6


@dataclass(frozen=True, kw_only=True, eq=False)
class Prototype:
    """Frozen data of a virtual prototype (build with ``build_prototype``).

    mechanism (mount offsets applied); transmissions: D1..D3; segment_stiffness
    (6, 5, 6, 6) K_jj [SI] per chain and segment; segment_stiffness_12 (6, 5, 12, 12) as the
    provider gave it; section_x (6, 6) [m] local x of the section nodes; assembly;
    initial_poses (29, 4, 4) undeformed body poses; settings; provider_description;
    chain_stiffness (6, 30, 30) [SI] or None: with a provider whose cuts are tied through
    section fields (``tied_chains.tied_fem_provider``), each chain's stiffness on its five segments'
    twists, which the frame then uses instead of the K_jj (``frame_stiffness``); the K_jj and
    the 12 x 12 are then the provider's ``chain_segments``, the same condensations with the cut
    fields held rigid (``cut_warping.rigid_part_stiffness``): effects change them, and the frame
    takes the change to K_chain (``frame_stiffness``).
    """

    mechanism: MechanismParams
    transmissions: tuple[ActuatorTransmission, ActuatorTransmission, ActuatorTransmission]
    segment_stiffness: np.ndarray
    segment_stiffness_12: np.ndarray
    section_x: np.ndarray
    assembly: Assembly
    initial_poses: np.ndarray
    settings: SolverSettings
    provider_description: str
    chain_stiffness: np.ndarray | None = None


@dataclass(frozen=True, kw_only=True, eq=False)
class PrototypeRun:
    """Result of ``simulate`` over n points.

    inputs (n, 3) [m] commands; screw_positions (n, 3) [m] after effects; angles (n, 3)
    [rad] as measured (after the effects' ``measure``; equal to true_angles without
    sensor effects); true_angles (n, 3) [rad] rotation vector of the frame; pose (n, 6)
    [m, rad]; axial_loads (n, 6) [N] tension positive, L1..L3, D1..D3; nut_offsets (n, 3)
    [m]; axial_stiffness (n, 3) [N/m] seen from each nut's anchor; point_class (n,) "S1",
    "S2" or "S3"; newton_iterations (n,) summed over the offset iterations;
    offset_iterations (n,); force_residual (n,) [N] and moment_residual (n,) [N m]: max
    equilibrium residual components at the returned state; wall_time [s]; provenance.
    """

    inputs: np.ndarray
    screw_positions: np.ndarray
    angles: np.ndarray
    true_angles: np.ndarray
    pose: np.ndarray
    axial_loads: np.ndarray
    nut_offsets: np.ndarray
    axial_stiffness: np.ndarray
    point_class: np.ndarray
    newton_iterations: np.ndarray
    offset_iterations: np.ndarray
    force_residual: np.ndarray
    moment_residual: np.ndarray
    wall_time: float
    provenance: dict


def apply_mount_offsets(mechanism: MechanismParams, offsets: Mapping[str, tuple[float, float]]) -> MechanismParams:
    """Move base points A by ``d (cos Phi y_loc + sin Phi z_loc)`` and rebuild the chains to fit.

    offsets: chain name -> (d [m], Phi [rad]); y_loc, z_loc are the chain's local axes
    before the offset. The chain's length becomes |B - A'| (built to fit, unstressed), its
    axes follow from A', B and the same roll reference. Returns a new ``MechanismParams``.
    """
    names = [c.name for c in mechanism.chains]
    unknown = sorted(set(offsets) - set(names))
    if unknown:
        raise ValueError(f"mount offsets name unknown chains {unknown}; chains are {names}")
    chains = []
    for placement in mechanism.chains:
        if placement.name not in offsets:
            chains.append(placement)
            continue
        d, phi = (float(v) for v in offsets[placement.name])
        axes = placement.rotation
        a_new = np.asarray(placement.point_a) + d * (np.cos(phi) * axes[:, 1] + np.sin(phi) * axes[:, 2])
        length = float(np.linalg.norm(np.asarray(placement.point_b) - a_new))
        chains.append(dataclasses.replace(placement, point_a=tuple(a_new),
                                          chain=dataclasses.replace(placement.chain, length=length)))
    return dataclasses.replace(mechanism, chains=tuple(chains))


def _transmissions(values: Sequence) -> tuple[ActuatorTransmission, ...]:
    if len(values) != 3:
        raise ValueError(f"need one transmission per driving chain (3), got {len(values)}")
    out = []
    for v in values:
        if isinstance(v, ActuatorTransmission):
            out.append(v)
        else:  # (x0, CL, mu, breakaway)
            x0, cl, mu, fb = v
            out.append(ActuatorTransmission(initial_position=x0, clearance=cl, hysteresis=mu, breakaway_force=fb))
    return tuple(out)


def prepare_prototype(mechanism: MechanismParams, provider: StiffnessProvider, *,
                      mount_offsets: Mapping[str, tuple[float, float]] | None = None) -> None:
    """Build at once what ``build_prototype`` of ``mechanism`` (with ``mount_offsets``, which move
    the chains' ends and so their lengths) asks ``provider`` for: its chains' FEM
    (``segments.prepare_chains``: tied chains or segments, in parallel)."""
    if mount_offsets:
        mechanism = apply_mount_offsets(mechanism, mount_offsets)
    prepare_chains(provider, [p.chain for p in mechanism.chains])


def _segment_stiffness(mechanism: MechanismParams, provider: StiffnessProvider):
    """(12 x 12, K_jj, section x) of every segment: ``provider(chain, x_start, x_end)``, or, for a
    provider with ``chain_segments(chain)`` (the tied one: its chains' five 12 x 12 from the
    condensations that give ``chain_stiffness``, so no segment is built twice), those; its
    ``prepare_chains(chains)`` first builds them at once."""
    k12 = np.zeros((N_CHAINS, N_SEGMENTS, 12, 12))
    xs = np.zeros((N_CHAINS, 6))
    asked: dict = {}  # equal chains (L1-L3, D1-D3 by default) ask the provider once
    by_chain = getattr(provider, "chain_segments", None)
    chain_matrices: dict = {}  # a chain's five 12 x 12 read once, not once per segment
    prepare_prototype(mechanism, provider)
    for c, placement in enumerate(mechanism.chains):
        xs[c] = section_nodes(placement.chain)
        for s in range(N_SEGMENTS):
            x0, x1 = xs[c, s], xs[c, s + 1]
            key = (placement.chain, float(x0), float(x1))
            if key not in asked:
                if callable(by_chain) and placement.chain not in chain_matrices:
                    chain_matrices[placement.chain] = by_chain(placement.chain)
                asked[key] = np.asarray(chain_matrices[placement.chain][s] if callable(by_chain)
                                        else provider(placement.chain, float(x0), float(x1)), dtype=float)
            k = asked[key]
            where = f"provider stiffness of {placement.name} segment {s} [{x0 * 1e3:.4g}, {x1 * 1e3:.4g}] mm"
            if k.shape != (12, 12) or not np.all(np.isfinite(k)):
                raise ValueError(f"{where} must be a finite (12, 12) array, got shape {k.shape}")
            if np.max(np.abs(k - k.T)) > 1e-8 * np.max(np.abs(k)):
                raise ValueError(f"{where} is not symmetric; a stiffness matrix must be")
            defect = rigid_mode_defect(k, x1 - x0)
            if defect > RIGID_DEFECT_LIMIT:
                raise ValueError(f"{where} does not vanish on rigid motions (defect {defect:.2g}); expected DOF order "
                                 "ux..rz of the start node then the end node, chain-local frame, SI")
            k12[c, s] = 0.5 * (k + k.T)
    kjj = end_stiffness(k12)
    if np.any(np.linalg.eigvalsh(kjj)[..., 0] <= 0):
        raise ValueError("a segment's end-node stiffness K_jj is not positive definite; check the provider")
    return k12, kjj, xs


def _chain_stiffness(mechanism: MechanismParams, provider: StiffnessProvider) -> np.ndarray | None:
    """(6, 30, 30) [SI] from ``provider.chain_stiffness(chain)`` (equal chains asked once), checked
    symmetric positive definite; None for a provider without it (rigid ties)."""
    ask = getattr(provider, "chain_stiffness", None)
    if not callable(ask):
        return None
    asked: dict = {}
    out = np.zeros((N_CHAINS, 6 * N_SEGMENTS, 6 * N_SEGMENTS))
    for c, placement in enumerate(mechanism.chains):
        if placement.chain not in asked:
            asked[placement.chain] = np.asarray(ask(placement.chain), dtype=float)
        k = asked[placement.chain]
        where = f"provider chain stiffness of {placement.name}"
        if k.shape != out.shape[1:] or not np.all(np.isfinite(k)):
            raise ValueError(f"{where} must be a finite {out.shape[1:]} array, got shape {k.shape}")
        if np.max(np.abs(k - k.T)) > 1e-8 * np.max(np.abs(k)):
            raise ValueError(f"{where} is not symmetric; a stiffness matrix must be")
        out[c] = 0.5 * (k + k.T)
    if np.any(np.linalg.eigvalsh(out)[..., 0] <= 0):
        raise ValueError("a chain stiffness on the segments' twists is not positive definite; check the provider")
    return out


def stiffness_congruence(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """T (..., 6, 6) with T^T K T = K' for symmetric positive definite K = ``before`` and K' =
    ``after`` (..., 6, 6) [SI]: the positive one, T = K^-1 (K # K') (# the matrix geometric
    mean), computed as L^-T (L^-1 K' L^-T)^(1/2) L^T from K = L L^T. For K' = s K, T = sqrt(s)
    I. Raises ``ValueError`` if K' is not positive definite (docs/effects.md, "Effects on tied
    cuts")."""
    L = np.linalg.cholesky(before)
    inverse = np.linalg.inv(L)
    middle = inverse @ after @ np.swapaxes(inverse, -1, -2)
    values, vectors = np.linalg.eigh(0.5 * (middle + np.swapaxes(middle, -1, -2)))
    if np.any(values <= 0):
        raise ValueError("an effect made a segment's stiffness K_jj not positive definite; with tied cuts (the provider "
                         "fem) its change acts on the chain's K_chain by a congruence that needs one")
    root = vectors @ (np.sqrt(values)[..., None] * np.swapaxes(vectors, -1, -2))
    return np.swapaxes(inverse, -1, -2) @ root @ np.swapaxes(L, -1, -2)


def tied_chain_stiffness(chain_stiffness: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """Each chain's K_chain (6, 30, 30) [SI] after effects changed its segments' K_jj from
    ``before`` to ``after`` (6, 5, 6, 6): T^T K_chain T, T = blockdiag(T_s) of the segments'
    ``stiffness_congruence`` (the identity for a segment left as it was). With K_chain the
    block diagonal of the K_jj this gives the block diagonal of the changed ones; a factor s_c
    on a whole chain scales its K_chain by s_c; per-segment factors s give S^1/2 K_chain S^1/2
    (docs/effects.md, "Effects on tied cuts")."""
    out = np.array(chain_stiffness, dtype=float)
    changed = np.any(before != after, axis=(-1, -2))
    for c in np.flatnonzero(np.any(changed, axis=1)):
        T = np.eye(6 * N_SEGMENTS)
        for s in np.flatnonzero(changed[c]):
            T[6 * s:6 * s + 6, 6 * s:6 * s + 6] = stiffness_congruence(before[c, s], after[c, s])
        k = T.T @ out[c] @ T
        out[c] = 0.5 * (k + k.T)
    return out


def frame_stiffness(prototype: Prototype, segment_stiffness: np.ndarray):
    """What the frame's equilibrium takes (``equilibrium.evaluate``): the K_jj
    ``segment_stiffness`` (6, 5, 6, 6) as (30, 6, 6), or, for a prototype with tied cuts
    (``chain_stiffness``), a ``CoupledStiffness`` of its chains, their K_chain changed as effects
    changed the K_jj from the prototype's own (``tied_chain_stiffness``)."""
    if prototype.chain_stiffness is None:
        return segment_stiffness.reshape(-1, 6, 6)
    blocks = prototype.chain_stiffness
    if not np.array_equal(segment_stiffness, prototype.segment_stiffness):
        blocks = tied_chain_stiffness(blocks, prototype.segment_stiffness, np.asarray(segment_stiffness, float))
    return CoupledStiffness(blocks=blocks, segments=np.arange(N_CHAINS * N_SEGMENTS).reshape(N_CHAINS, N_SEGMENTS))


def _assembly(mechanism: MechanismParams, xs: np.ndarray):
    selection = [np.eye(6)] + [np.eye(6)] * 24 + [np.eye(6)[:, :1]] * 3 + [np.zeros((6, 0))]
    poses0 = np.broadcast_to(np.eye(4), (29, 4, 4)).copy()
    node_body, node_offset, seg_nodes, seg_ref = [], [], [], []
    for c, placement in enumerate(mechanism.chains):
        rot, a = placement.rotation, np.asarray(placement.point_a, dtype=float)
        node_poses0 = pose(rot, a + xs[c][:, None] * rot[:, 0])  # (6, 4, 4)
        if placement.is_driving:
            nut = NUT_BODIES[c - 3]
            poses0[nut] = node_poses0[0]
            node_body.append(nut)
            node_offset.append(np.eye(4))
        else:
            node_body.append(GROUND_BODY)
            node_offset.append(node_poses0[0])
        for k in range(4):
            body = INTERIOR_BODIES[c, k]
            poses0[body] = node_poses0[k + 1]
            node_body.append(body)
            node_offset.append(np.eye(4))
        node_body.append(FRAME_BODY)
        node_offset.append(node_poses0[5])  # frame design pose is the identity
        for s in range(N_SEGMENTS):
            seg_nodes.append((6 * c + s, 6 * c + s + 1))
            seg_ref.append(translation_pose(np.array([-(xs[c, s + 1] - xs[c, s]), 0.0, 0.0])))
    assembly = build_assembly(selection, node_body, np.array(node_offset), seg_nodes, np.array(seg_ref))
    return assembly, poses0


def build_prototype(mechanism: MechanismParams, transmissions: Sequence, provider: StiffnessProvider, *,
                    mount_offsets: Mapping[str, tuple[float, float]] | None = None,
                    settings: SolverSettings = SolverSettings()) -> Prototype:
    """A ``Prototype`` (frozen) of ``mechanism``.

    transmissions: three ``ActuatorTransmission`` (or tuples (x0 [m], CL [m], mu [-],
    breakaway [N])) for D1..D3; provider: ``provider(chain, x_start, x_end) -> (12, 12)``
    (``flexcal.validation.prototype.segments``), called 30 times; mount_offsets: chain name ->
    (d [m], Phi [rad]) (``apply_mount_offsets``). Raises ``ValueError`` naming the bad input.
    """
    if mount_offsets:
        mechanism = apply_mount_offsets(mechanism, mount_offsets)
    k12, kjj, xs = _segment_stiffness(mechanism, provider)
    chains = _chain_stiffness(mechanism, provider)
    assembly, poses0 = _assembly(mechanism, xs)
    for array in (k12, kjj, xs, poses0) + (() if chains is None else (chains,)):
        array.setflags(write=False)
    description = getattr(provider, "description", getattr(provider, "__name__", type(provider).__name__))
    return Prototype(mechanism=mechanism, transmissions=_transmissions(transmissions), segment_stiffness=kjj,
                     segment_stiffness_12=k12, section_x=xs, assembly=assembly, initial_poses=poses0,
                     settings=settings, provider_description=str(description), chain_stiffness=chains)


def _loads(prototype: Prototype, conditions: PointConditions, anchors: np.ndarray) -> Loads:
    forces = tuple((FRAME_BODY, np.asarray(f, float), np.asarray(p, float)) for f, p in conditions.frame_forces)
    springs = []
    for i, placement in enumerate(prototype.mechanism.driving_chains):
        springs.append((NUT_BODIES[i], float(conditions.actuator_stiffness[i]), placement.rotation[:, 0],
                        np.asarray(placement.point_a, dtype=float), float(anchors[i])))
    return Loads(point_forces=forces, springs=tuple(springs))


def _axial_state(prototype: Prototype, info, actuator_stiffness: np.ndarray):
    """Chain tensions (6,) [N] and the axial stiffness (3,) [N/m] seen from each nut's anchor."""
    first = info.segment_gradient.reshape(N_CHAINS, N_SEGMENTS, 12)[:, 0, 0]
    tension = -first  # force of the chain on node A along +x (towards B)
    dofs = prototype.assembly.dof_start[list(NUT_BODIES)]
    unit = np.zeros((prototype.assembly.n_dofs, 3))
    unit[dofs, np.arange(3)] = 1.0
    flexibility = np.diag(scipy.linalg.solve(info.tangent, unit, assume_a="sym")[dofs])
    k_a = np.asarray(actuator_stiffness, dtype=float)
    return tension, k_a - k_a**2 * flexibility


def _hook(effects, name):
    return [getattr(e, name) for e in effects if callable(getattr(e, name, None))]


def _apply_condition_hooks(conditions: PointConditions, hooks, name: str, *args) -> PointConditions:
    """``conditions`` after the hooks ``name`` (``modify_mechanism``: args = (context,);
    ``modify_loaded_mechanism``: args = (axial_loads, context)), each checked to return
    ``PointConditions``."""
    for hook in hooks:
        conditions = hook(conditions, *args)
        if not isinstance(conditions, PointConditions):
            raise ValueError(f"{name} of effect {hook.__self__.name!r} must return PointConditions "
                             "(use dataclasses.replace on the one it was given)")
    return conditions


def _with_loads(conditions: PointConditions, axial_loads, hooks, context) -> PointConditions:
    """``conditions`` after the ``modify_loaded_mechanism`` hooks at ``axial_loads`` (6,)
    [N] (unchanged while no loads are known: the first iterate of the first point)."""
    if axial_loads is None:
        return conditions
    return _apply_condition_hooks(conditions, hooks, "modify_loaded_mechanism",
                                  np.array(axial_loads, dtype=float), context)


def simulate(prototype: Prototype, inputs: np.ndarray, *, effects: Iterable[Any] = (),
             progress: bool = False, time: np.ndarray | None = None,
             temperature: np.ndarray | None = None) -> PrototypeRun:
    """Walk the trajectory ``inputs`` (n_points, 3) [m] (commands of D1..D3, positive A -> B).

    time (n_points,) [s] non-decreasing, default 1 s per point (0, 1, 2, ...); temperature
    (n_points,) [degC] of the room, default ``room_temperature(time, seed=0)``. Both only
    reach the effects (``EffectContext``); the nominal physics is isothermal and static.
    Returns a ``PrototypeRun``. Raises ``ValueError`` for bad inputs and
    ``NonConvergenceError`` if an equilibrium or the nut offsets do not converge. Runs on
    one BLAS thread (``flexcal.validation.blas_threads``: small factorizations are far
    faster that way on a loaded machine).
    """
    with single_blas_thread():
        return _simulate(prototype, inputs, tuple(effects), progress, time, temperature)


def _time_and_temperature(n: int, time, temperature) -> tuple[np.ndarray, np.ndarray]:
    times = np.arange(n, dtype=float) if time is None else np.array(time, dtype=float)
    if times.shape != (n,) or not np.all(np.isfinite(times)) or np.any(np.diff(times) < 0):
        raise ValueError(f"time must be a finite, non-decreasing ({n},) array in s, got shape {times.shape}")
    temps = room_temperature(times) if temperature is None else np.array(temperature, dtype=float)
    if temps.shape != (n,) or not np.all(np.isfinite(temps)):
        raise ValueError(f"temperature must be a finite ({n},) array in degC, got shape {temps.shape}")
    return times, temps


def _offsets_not_converged(k: int, settings: SolverSettings, change: np.ndarray, load_change: float,
                           offsets: np.ndarray, load_dependent: bool) -> str:
    """The message of a nut-offset fixed point that did not settle, naming the knob."""
    text = (f"nut offsets (and load-dependent effects' loads) did not converge at point {k} within "
            f"{settings.max_offset_iterations} iterations (last change {np.max(np.abs(change)):.3g} m, "
            f"{load_change:.3g} N)")
    if load_dependent and load_change > settings.load_tolerance:
        return text + "; a load-dependent effect keeps changing the loads: reduce its magnitude in [[effects]]"
    drives = [f"D{i + 1}" for i in range(3) if offsets[i] > 0] or ["D1", "D2", "D3"]
    knobs = ", ".join(f"'{d}.mu', '{d}.CL'" for d in drives)
    return (text + f"; {'/'.join(drives)} sit in their clearance there: set {knobs} under [errors] of the scenario "
            f"(Table 1: mu 0.83-0.93, CL 0.10-0.42 mm) or try another --seed")


def _simulate(prototype: Prototype, inputs: np.ndarray, effects: tuple, progress: bool, time_s, temperature
              ) -> PrototypeRun:
    inputs = np.asarray(inputs, dtype=float)
    if inputs.ndim != 2 or inputs.shape[1] != 3 or not np.all(np.isfinite(inputs)):
        raise ValueError(f"inputs must be a finite (n_points, 3) array in m, got shape {inputs.shape}")
    times, temps = _time_and_temperature(len(inputs), time_s, temperature)
    commands = inputs.copy()
    for array in (commands, times, temps):
        array.setflags(write=False)  # effects see slices of these
    history: list[PointResult] = []
    records = [effect_record(e) for e in effects]
    mech, settings, tr = prototype.mechanism, prototype.settings, prototype.transmissions
    x0 = np.array([t.initial_position for t in tr])
    mu = np.array([t.hysteresis for t in tr])
    clearance = np.array([t.clearance for t in tr])
    breakaway = np.array([t.breakaway_force for t in tr])
    weight = (mech.payload_mass * np.asarray(mech.gravity, dtype=float), np.asarray(mech.centre_of_gravity, float))
    n = len(inputs)
    out = {k: np.zeros((n, w)) for k, w in [("screw", 3), ("angles", 3), ("true", 3), ("pose", 6), ("loads", 6),
                                            ("offsets", 3), ("stiff", 3)]}
    iters, outer_iters = np.zeros(n, int), np.zeros(n, int)
    f_res, m_res = np.zeros(n), np.zeros(n)
    classes = np.empty(n, dtype="<U2")
    poses, tangent = prototype.initial_poses.copy(), None
    previous_offsets, previous_result = None, None
    direction, last_command = np.ones(3), inputs[0].copy()
    points = range(n)
    if progress:
        from ..progress import progress_iter

        points = progress_iter(points, "prototype", unit="point")
    start = time.perf_counter()
    for k in points:
        command = inputs[k]
        # travel direction: sign of the last move > MIN_MOVE, +1 before any (docs/conventions.md)
        direction = next_direction(direction, command - last_command)
        last_command = command
        context = EffectContext(point_index=k, command=command.copy(), direction=direction.copy(),
                                previous=previous_result, time=float(times[k]),
                                dwell=float(times[k] - times[k - 1]) if k else 0.0, temperature=float(temps[k]),
                                past_commands=commands[:k + 1], past_times=times[:k + 1],
                                past_temperatures=temps[:k + 1], history=tuple(history))
        screw = command + x0
        for hook in _hook(effects, "modify_screw_position"):
            screw = np.array([float(hook(i, float(command[i]), float(screw[i]), context)) for i in range(3)])
        stiffness = np.array(prototype.segment_stiffness)
        for hook in _hook(effects, "modify_stiffness"):
            stiffness = np.asarray(hook(stiffness.copy(), context), dtype=float)
        conditions = PointConditions(segment_stiffness=stiffness, frame_forces=(weight,),
                                     actuator_stiffness=np.full(3, float(mech.actuator_stiffness)))
        conditions = _apply_condition_hooks(conditions, _hook(effects, "modify_mechanism"), "modify_mechanism",
                                            context)
        # load-dependent effects see the loads of this point: first guess the previous
        # point's, then the iterate's, solved together with the nut offsets below
        loaded_hooks = _hook(effects, "modify_loaded_mechanism")
        base, guess = conditions, None if previous_result is None else previous_result.axial_loads
        conditions = _with_loads(base, guess, loaded_hooks, context)
        offsets = np.zeros(3) if previous_offsets is None else previous_offsets.copy()
        iterates, images = [], []
        for outer in range(1, settings.max_offset_iterations + 1):
            loads = _loads(prototype, conditions, screw + offsets)
            poses, info = solve_equilibrium(prototype.assembly, poses,
                                            frame_stiffness(prototype, conditions.segment_stiffness),
                                            loads, settings, where=f"at point {k}", tangent=tangent)
            tangent = info.tangent
            iters[k] += info.iterations
            tension, axial = _axial_state(prototype, info, conditions.actuator_stiffness)
            new = nut_offset(previous_offsets, tension[3:], axial, offsets, mu, clearance, breakaway)
            load_change = 0.0 if not loaded_hooks else np.inf if guess is None else np.max(np.abs(tension - guess))
            if np.max(np.abs(new - offsets)) <= settings.offset_tolerance and load_change <= settings.load_tolerance:
                break
            # plain fixed point; once it has not settled, accelerated (slow contraction with
            # two chains off their flanks) or damped (a 2-cycle at a wall): fixed_point.py
            if outer < 10:
                offsets = new
            else:
                iterates.append(offsets)
                images.append(new)
                offsets, restart = anderson_step(iterates, images, clearance)
                if restart:
                    iterates, images = [], []
            if loaded_hooks:
                guess = tension
                conditions = _with_loads(base, guess, loaded_hooks, context)
        else:
            raise NonConvergenceError(_offsets_not_converged(k, settings, new - offsets, load_change, offsets,
                                                             bool(loaded_hooks)))
        outer_iters[k] = outer
        rotation_vector = so3_log(poses[FRAME_BODY, :3, :3])
        measured = rotation_vector.copy()
        for hook in _hook(effects, "measure"):
            measured = np.asarray(hook(measured.copy(), context), dtype=float)
        out["screw"][k], out["true"][k], out["angles"][k] = screw, rotation_vector, measured
        out["pose"][k] = np.r_[poses[FRAME_BODY, :3, 3], rotation_vector]
        out["loads"][k], out["offsets"][k], out["stiff"][k] = tension, offsets, axial
        f_res[k], m_res[k] = info.force_residual, info.moment_residual
        classes[k] = point_class(tension[3:], offsets)
        previous_offsets = offsets.copy()
        previous_result = PointResult(angles=rotation_vector, pose=out["pose"][k].copy(), axial_loads=tension,
                                      nut_offsets=offsets.copy())
        history.append(previous_result)
    wall = time.perf_counter() - start
    provenance = {
        "generator": "flexcal.validation.prototype.mechanism.simulate",
        "provider": prototype.provider_description,
        "transmissions": [dataclasses.asdict(t) for t in tr],
        "solver": dataclasses.asdict(settings),
        "effects": records,
        "angles": "rotation vector of the frame rotation relative to the design pose [rad]",
    }
    return PrototypeRun(inputs=inputs.copy(), screw_positions=out["screw"], angles=out["angles"],
                        true_angles=out["true"], pose=out["pose"], axial_loads=out["loads"],
                        nut_offsets=out["offsets"], axial_stiffness=out["stiff"], point_class=classes,
                        newton_iterations=iters, offset_iterations=outer_iters, force_residual=f_res,
                        moment_residual=m_res, wall_time=wall, provenance=provenance)
