"""Static equilibrium of rigid bodies joined by segment superelements: Newton on SE(3).

An ``Assembly`` is bodies, nodes and segments:

- a **body** has a pose (4 x 4) and a DOF selection ``S_b`` (6 x n_b): its body-frame
  perturbation is ``delta_b = S_b q_b`` (``I6`` for a free body, ``e1`` for an actuator nut
  sliding along its local x, an empty matrix for ground);
- a **node** is rigidly attached to a body at a fixed offset pose ``O`` (pose = ``T_b O``),
  so ``delta_node = Ad(O^-1) S_b q_b`` exactly;
- a **segment** joins two nodes (``flexcal.validation.prototype.superelement``).

Loads: constant world forces at body points (gravity of the payload) and axial springs
on translation-only bodies (the actuators' screw/coupling contact stiffness,
energy ``1/2 k (d . (p - p_ref) - anchor)^2``).

``solve_equilibrium`` minimizes the total potential by Newton's method with the
consistent tangent (superelement module: symmetrized central differences of the exact
gradient; loads analytic), manifold updates ``T_b <- T_b exp(S_b dq_b)``, and a
backtracking line search on the scaled residual norm. It stops when every force
component of the residual (generalized force of a translational DOF) is below
``force_tolerance`` [N] and every moment component below ``moment_tolerance`` [N m].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from .kinematics import hat, orthonormalize, se3_adjoint, se3_exp, se3_inverse
from .superelement import (DEFAULT_STEP, CoupledStiffness, relative_pose, segment_deformation, segment_energy,
                           segment_gradient, segment_jacobian, segment_tangent)

__all__ = [
    "SolverSettings",
    "Assembly",
    "Loads",
    "EquilibriumInfo",
    "NonConvergenceError",
    "build_assembly",
    "node_poses",
    "evaluate",
    "solve_equilibrium",
]


class NonConvergenceError(RuntimeError):
    """Newton did not reach the residual tolerances (message says where and by how much)."""


@dataclass(frozen=True, kw_only=True)
class SolverSettings:
    """Tolerances and limits of the prototype's solvers.

    force_tolerance [N], moment_tolerance [N m]: Newton stops when every residual
    component is below them. The defaults are ~3e-9 of the payload's weight (2943 N) and
    ~2e-8 of its moment about O_C (441 N m). They sit above the round-off floor: node
    positions of ~0.6 m are stored to ~1e-16 m, and the stiffest segments (~2e9 N/m)
    turn that into ~1e-6 N of force noise and, over the frame's ~0.6 m lever arms, ~3e-7
    N m of moment noise. The displacement error they allow is < 1e-14 m and < 1e-11 rad;
    max_iterations: Newton iterations per equilibrium; offset_tolerance [m]: the nut
    offsets' fixed point stops when no offset moves more than this; load_tolerance [N]: and,
    with load-dependent effects, when no chain's axial load moves more than this (10x the
    force tolerance: the Newton solution's own load noise; 1e-4 N of 3 kN changes a
    load-dependent stiffness by ~3e-8 of itself); max_offset_iterations;
    step [m or rad]: central-difference step of the tangent.
    """

    force_tolerance: float = 1e-5
    moment_tolerance: float = 1e-5
    max_iterations: int = 40
    offset_tolerance: float = 1e-12
    load_tolerance: float = 1e-4
    max_offset_iterations: int = 30
    step: float = DEFAULT_STEP

    def __post_init__(self) -> None:
        for name in ("force_tolerance", "moment_tolerance", "offset_tolerance", "load_tolerance", "step"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}={getattr(self, name)!r} must be > 0")
        for name in ("max_iterations", "max_offset_iterations"):
            if not getattr(self, name) >= 1:
                raise ValueError(f"{name}={getattr(self, name)!r} must be >= 1")


@dataclass(frozen=True, kw_only=True, eq=False)
class Assembly:
    """Topology and constant geometry (module docstring); build with ``build_assembly``.

    body_selection: tuple of (6, n_b) DOF selections; dof_start (n_bodies,) first global
    DOF of each body; n_dofs; node_body (n_nodes,) int; node_offset (n_nodes, 4, 4);
    segment_nodes (n_segments, 2) int (start, end); segment_reference_inverse
    (n_segments, 4, 4) = D of the superelement; segment_map (n_segments, 12, 12) and
    segment_dofs (n_segments, 12) int: the segment's node perturbations are
    ``segment_map @ q[segment_dofs]`` (index n_dofs is a dummy with zero columns);
    dof_is_rotation (n_dofs,) bool.
    """

    body_selection: tuple[np.ndarray, ...]
    dof_start: np.ndarray
    n_dofs: int
    node_body: np.ndarray
    node_offset: np.ndarray
    segment_nodes: np.ndarray
    segment_reference_inverse: np.ndarray
    segment_map: np.ndarray
    segment_dofs: np.ndarray
    dof_is_rotation: np.ndarray


def build_assembly(body_selection, node_body, node_offset, segment_nodes, segment_reference_inverse) -> Assembly:
    """Precompute DOF numbering and the linear maps of an ``Assembly`` (see its docstring)."""
    selection = tuple(np.asarray(s, dtype=float).reshape(6, -1) for s in body_selection)
    sizes = np.array([s.shape[1] for s in selection])
    dof_start = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)
    n_dofs = int(sizes.sum())
    node_body = np.asarray(node_body, dtype=int)
    node_offset = np.asarray(node_offset, dtype=float)
    node_map = np.zeros((len(node_body), 6, 6))
    node_dofs = np.full((len(node_body), 6), n_dofs)
    adjoints = se3_adjoint(se3_inverse(node_offset))
    for n, b in enumerate(node_body):
        node_map[n, :, :sizes[b]] = adjoints[n] @ selection[b]
        node_dofs[n, :sizes[b]] = dof_start[b] + np.arange(sizes[b])
    segment_nodes = np.asarray(segment_nodes, dtype=int)
    segment_map = np.zeros((len(segment_nodes), 12, 12))
    segment_map[:, :6, :6] = node_map[segment_nodes[:, 0]]
    segment_map[:, 6:, 6:] = node_map[segment_nodes[:, 1]]
    segment_dofs = np.concatenate([node_dofs[segment_nodes[:, 0]], node_dofs[segment_nodes[:, 1]]], axis=1)
    rotation = np.concatenate([np.any(s[3:] != 0, axis=0) for s in selection]) if n_dofs else np.zeros(0, bool)
    return Assembly(body_selection=selection, dof_start=dof_start, n_dofs=n_dofs, node_body=node_body,
                    node_offset=node_offset, segment_nodes=segment_nodes,
                    segment_reference_inverse=np.asarray(segment_reference_inverse, dtype=float),
                    segment_map=segment_map, segment_dofs=segment_dofs, dof_is_rotation=rotation)


@dataclass(frozen=True, kw_only=True, eq=False)
class Loads:
    """External loads of one equilibrium.

    point_forces: tuple of (body index, force (3,) [N] in the world frame, point (3,) [m]
    in the body frame) -- constant (dead) forces, e.g. the payload's weight at its centre
    of gravity. springs: tuple of (body index, stiffness [N/m], direction (3,) world unit
    vector, reference point (3,) [m] world, anchor [m]) -- energy
    ``1/2 k (d . (p_b - p_ref) - anchor)^2`` on a body whose DOFs are translations only.
    """

    point_forces: tuple = ()
    springs: tuple = ()


@dataclass(frozen=True, kw_only=True, eq=False)
class EquilibriumInfo:
    """iterations (Newton steps taken), force_residual [N], moment_residual [N m] (max
    absolute components at the returned poses), tangent (n_dofs, n_dofs) [SI] at the last
    iterate where it was formed, segment_gradient (n_segments, 12) [N, N m] at the
    returned poses."""

    iterations: int
    force_residual: float
    moment_residual: float
    tangent: np.ndarray
    segment_gradient: np.ndarray


def node_poses(assembly: Assembly, body_poses: np.ndarray) -> np.ndarray:
    """World poses (n_nodes, 4, 4) of the nodes from the body poses (n_bodies, 4, 4)."""
    return body_poses[assembly.node_body] @ assembly.node_offset


def _load_terms(assembly: Assembly, body_poses: np.ndarray, loads: Loads, with_tangent: bool):
    """Potential [J], gradient (n_dofs,) and Hessian (n_dofs, n_dofs) of the external loads."""
    energy, grad = 0.0, np.zeros(assembly.n_dofs)
    hess = np.zeros((assembly.n_dofs, assembly.n_dofs)) if with_tangent else None
    for body, force, point in loads.point_forces:
        rot, pos = body_poses[body, :3, :3], body_poses[body, :3, 3]
        force, point = np.asarray(force, float), np.asarray(point, float)
        f_body = rot.T @ force
        energy -= force @ (pos + rot @ point)
        g6 = -np.r_[f_body, np.cross(point, f_body)]
        sel, start = assembly.body_selection[body], assembly.dof_start[body]
        idx = slice(start, start + sel.shape[1])
        grad[idx] += sel.T @ g6
        if with_tangent:  # second-order terms of p + R (J_l(w) v + exp(w) c), see docs/prototype.md
            h6 = np.zeros((6, 6))
            h6[3:, :3] = 0.5 * hat(f_body)
            h6[:3, 3:] = -0.5 * hat(f_body)
            h6[3:, 3:] = -0.5 * (np.outer(f_body, point) + np.outer(point, f_body)) + (f_body @ point) * np.eye(3)
            hess[idx, idx] += sel.T @ h6 @ sel
    for body, stiffness, direction, reference, anchor in loads.springs:
        rot, pos = body_poses[body, :3, :3], body_poses[body, :3, 3]
        sel, start = assembly.body_selection[body], assembly.dof_start[body]
        if np.any(sel[3:] != 0):
            raise ValueError("axial springs act on translation-only bodies (actuator nuts)")
        idx = slice(start, start + sel.shape[1])
        stretch = float(np.dot(direction, pos - reference) - anchor)
        d_body = sel.T @ np.r_[rot.T @ np.asarray(direction, float), np.zeros(3)]
        energy += 0.5 * stiffness * stretch**2
        grad[idx] += stiffness * stretch * d_body
        if with_tangent:
            hess[idx, idx] += stiffness * np.outer(d_body, d_body)
    return energy, grad, hess


def evaluate(assembly: Assembly, body_poses: np.ndarray, stiffness, loads: Loads,
             with_tangent: bool = True, step: float = DEFAULT_STEP):
    """Total potential [J], residual (n_dofs,) [N, N m], tangent (n_dofs, n_dofs) or None,
    and the segment gradients (n_segments, 12), at ``body_poses`` (n_bodies, 4, 4).

    ``stiffness``: each segment's K_jj (n_segments, 6, 6) [SI], or a ``CoupledStiffness``
    (groups of segments with one stiffness on their twists, ``superelement``).
    """
    nodes = node_poses(assembly, body_poses)
    rel = relative_pose(nodes[assembly.segment_nodes[:, 0]], nodes[assembly.segment_nodes[:, 1]])
    d = assembly.segment_reference_inverse
    if isinstance(stiffness, CoupledStiffness):
        return _evaluate_coupled(assembly, body_poses, rel, stiffness, loads, with_tangent, step)
    seg_grad = segment_gradient(rel, d, stiffness)
    energy_l, grad_l, hess_l = _load_terms(assembly, body_poses, loads, with_tangent)
    energy = float(np.sum(segment_energy(rel, d, stiffness))) + energy_l
    residual = _gathered_residual(assembly, seg_grad) + grad_l
    tangent = None
    if with_tangent:
        tangent = _gathered_tangent(assembly, segment_tangent(rel, d, stiffness, step), hess_l)
    return energy, residual, tangent, seg_grad


def _gathered_residual(assembly: Assembly, seg_grad: np.ndarray) -> np.ndarray:
    """(n_dofs,): the segments' gradients (n_segments, 12) mapped to and summed on the DOFs."""
    n, m, dofs = assembly.n_dofs, assembly.segment_map, assembly.segment_dofs
    local = np.einsum("ska,sk->sa", m, seg_grad)  # M^T g per segment
    return np.bincount(dofs.ravel(), weights=local.ravel(), minlength=n + 1)[:n]


def _gathered_tangent(assembly: Assembly, seg_tangent: np.ndarray, hess_l: np.ndarray,
                      cross: np.ndarray | None = None, groups: np.ndarray | None = None) -> np.ndarray:
    """(n_dofs, n_dofs), symmetrized: the segments' tangents (n_segments, 12, 12) mapped and summed,
    plus the loads' Hessian; cross (n_groups, 12 m, 12 m): blocks between the node DOFs of the
    segments ``groups`` (n_groups, m) (a coupled group's cross-segment terms)."""
    n, m, dofs = assembly.n_dofs, assembly.segment_map, assembly.segment_dofs
    seg_tan = np.swapaxes(m, -1, -2) @ seg_tangent @ m
    flat = dofs[:, :, None] * (n + 1) + dofs[:, None, :]
    values, where = [seg_tan.ravel()], [flat.ravel()]
    if cross is not None:
        n_groups, size = groups.shape
        maps = m[groups]  # (g, m, 12, 12)
        big = np.zeros((n_groups, 12 * size, 12 * size))
        for s in range(size):
            big[:, 12 * s:12 * s + 12, 12 * s:12 * s + 12] = maps[:, s]
        mapped = np.swapaxes(big, -1, -2) @ cross @ big
        group_dofs = dofs[groups].reshape(n_groups, -1)
        values.append(mapped.ravel())
        where.append((group_dofs[:, :, None] * (n + 1) + group_dofs[:, None, :]).ravel())
    tangent = np.bincount(np.concatenate(where), weights=np.concatenate(values), minlength=(n + 1) ** 2)
    tangent = tangent.reshape(n + 1, n + 1)[:n, :n] + hess_l
    return 0.5 * (tangent + tangent.T)


def _evaluate_coupled(assembly: Assembly, body_poses: np.ndarray, rel: np.ndarray, stiffness: CoupledStiffness,
                      loads: Loads, with_tangent: bool, step: float):
    """``evaluate`` for coupled segments (``superelement`` module docstring): energy 1/2 Xi^T K Xi
    per group, each segment's gradient (3) with its share (K Xi)_s of the wrench, the tangent's
    segment blocks by central differences with the other segments' share held fixed and the
    cross-segment blocks J_s^T K_st J_t."""
    d = assembly.segment_reference_inverse
    if stiffness.n_segments != len(rel):
        raise ValueError(f"the coupled stiffness covers {stiffness.n_segments} segments, the assembly has {len(rel)}")
    xi = segment_deformation(rel, d)
    diagonal = stiffness.diagonal()
    wrench = stiffness.wrench(xi)
    offset = wrench - np.einsum("sij,sj->si", diagonal, xi)
    seg_grad = segment_gradient(rel, d, diagonal, offset, deformation=xi)
    energy_l, grad_l, hess_l = _load_terms(assembly, body_poses, loads, with_tangent)
    energy = 0.5 * float(np.sum(xi * wrench)) + energy_l
    residual = _gathered_residual(assembly, seg_grad) + grad_l
    tangent = None
    if with_tangent:
        groups = stiffness.segments
        n_groups, size = groups.shape
        jacobian = segment_jacobian(rel, d)[groups]  # (g, m, 6, 12)
        blocks = stiffness.blocks.reshape(n_groups, size, 6, size, 6).copy()
        blocks[:, np.arange(size), :, np.arange(size), :] = 0.0  # the segments' own blocks: in their tangents
        cross = np.einsum("gsai,gsatb,gtbj->gsitj", jacobian, blocks, jacobian).reshape(n_groups, 12 * size,
                                                                                      12 * size)
        tangent = _gathered_tangent(assembly, segment_tangent(rel, d, diagonal, step, offset), hess_l, cross, groups)
    return energy, residual, tangent, seg_grad


def _update(assembly: Assembly, body_poses: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """``T_b <- T_b exp(S_b dq_b)`` for every body with DOFs."""
    out = body_poses.copy()
    twists = np.zeros((len(assembly.body_selection), 6))
    for b, sel in enumerate(assembly.body_selection):
        if sel.shape[1]:
            twists[b] = sel @ dq[assembly.dof_start[b]:assembly.dof_start[b] + sel.shape[1]]
    return orthonormalize(out @ se3_exp(twists))


def _residual_norms(assembly: Assembly, residual: np.ndarray) -> tuple[float, float]:
    rot = assembly.dof_is_rotation
    force = float(np.max(np.abs(residual[~rot]), initial=0.0))
    moment = float(np.max(np.abs(residual[rot]), initial=0.0))
    return force, moment


def _factor(tangent: np.ndarray, where: str):
    try:
        return ("cho", scipy.linalg.cho_factor(tangent))
    except np.linalg.LinAlgError:
        pass  # not positive definite (far from a stable equilibrium): fall back to LU
    try:
        with np.errstate(all="raise"):
            return ("lu", scipy.linalg.lu_factor(tangent, check_finite=True))
    except (np.linalg.LinAlgError, FloatingPointError, ValueError) as error:
        raise NonConvergenceError(f"singular tangent {where}: the mechanism has a free motion "
                                  f"(check the chains and supports): {error}") from error


def _solve(factor, rhs: np.ndarray) -> np.ndarray:
    kind, data = factor
    return scipy.linalg.cho_solve(data, rhs) if kind == "cho" else scipy.linalg.lu_solve(data, rhs)


def solve_equilibrium(assembly: Assembly, body_poses: np.ndarray, stiffness: np.ndarray, loads: Loads,
                      settings: SolverSettings = SolverSettings(), where: str = "",
                      tangent: np.ndarray | None = None,
                      final_tangent: bool = True) -> tuple[np.ndarray, EquilibriumInfo]:
    """Newton from ``body_poses`` (warm start) to equilibrium; returns (poses, info).

    ``tangent`` (optional): a tangent from a nearby state (the previous trajectory point)
    to start with. Steps use the newest tangent as long as each step at least halves the
    scaled residual norm (chord Newton); otherwise the tangent is re-formed at the current
    state, and with a fresh tangent a backtracking line search guards the step. The
    returned ``info.tangent`` is formed at the returned poses (``final_tangent=False``: the
    last one formed on the way, for a caller that only reads the segment gradients; the
    poses and gradients are the same bits either way). Raises
    ``NonConvergenceError`` (naming ``where``) if the tolerances are not met within
    ``settings.max_iterations`` steps or the residual stalls above them.
    """
    poses = np.array(body_poses, dtype=float)
    scale = np.where(assembly.dof_is_rotation, 1.0 / settings.moment_tolerance, 1.0 / settings.force_tolerance)
    fresh = tangent is None
    if fresh:
        _, residual, tangent, seg_grad = evaluate(assembly, poses, stiffness, loads, True, settings.step)
    else:
        _, residual, _, seg_grad = evaluate(assembly, poses, stiffness, loads, False, settings.step)
    factor = _factor(tangent, where)
    iteration, stalls = 0, 0
    while True:
        force, moment = _residual_norms(assembly, residual)
        if force <= settings.force_tolerance and moment <= settings.moment_tolerance:
            if not fresh and final_tangent:
                _, residual, tangent, seg_grad = evaluate(assembly, poses, stiffness, loads, True, settings.step)
            return poses, EquilibriumInfo(iterations=iteration, force_residual=force, moment_residual=moment,
                                          tangent=tangent, segment_gradient=seg_grad)
        if iteration >= settings.max_iterations or stalls >= 3:
            break
        merit = np.linalg.norm(scale * residual)
        dq = -_solve(factor, residual)
        trial = _update(assembly, poses, dq)
        _, trial_res, _, trial_grad = evaluate(assembly, trial, stiffness, loads, False, settings.step)
        trial_merit = np.linalg.norm(scale * trial_res)
        if not fresh and not trial_merit <= 0.5 * merit:
            # the old tangent no longer contracts: re-form it here and retry
            _, residual, tangent, seg_grad = evaluate(assembly, poses, stiffness, loads, True, settings.step)
            factor, fresh = _factor(tangent, where), True
            continue
        best, alpha = (trial_merit, trial, trial_res, trial_grad), 1.0
        while fresh and best[0] >= merit and alpha > 1e-3:  # backtracking on the scaled residual norm
            alpha *= 0.5
            trial = _update(assembly, poses, alpha * dq)
            _, trial_res, _, trial_grad = evaluate(assembly, trial, stiffness, loads, False, settings.step)
            trial_merit = np.linalg.norm(scale * trial_res)
            if trial_merit < best[0]:
                best = (trial_merit, trial, trial_res, trial_grad)
        stalls = stalls + 1 if best[0] >= merit else 0
        _, poses, residual, seg_grad = best
        iteration += 1
        fresh = False
    force, moment = _residual_norms(assembly, residual)
    raise NonConvergenceError(
        f"Newton did not converge {where} ({iteration} iterations): force residual "
        f"{force:.3g} N (tolerance {settings.force_tolerance:.3g}), moment residual {moment:.3g} N m "
        f"(tolerance {settings.moment_tolerance:.3g}); loosen SolverSettings or check for buckling")
