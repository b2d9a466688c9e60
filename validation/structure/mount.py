"""The mount as a structure, on the virtual prototype's reduced model.

The prototype (``flexcal.validation.prototype.mechanism``) holds the payload frame
(body 0, 6 DOF at O_C), the four interior section nodes of every chain (6 DOF each) and
the three actuator nuts (1 DOF along their chain), joined by the chains' segment
superelements (12 x 12 stiffness from a provider: beam theory or condensed FEM). At the
nominal state (design commands, the payload's weight) Newton's tangent K_T is the
mount's stiffness there, geometric (axial load x rotation) terms included. On the same
DOFs this module adds:

* the mass: each segment's 12 x 12 mass (``segment_mass``) through the same node maps as
  its stiffness, plus the payload as a rigid body at O_C (``payload_mass_matrix``);
* ``mount_modes``: K_T phi = omega^2 M phi (shift-invert Lanczos), frequencies [Hz] and
  effective masses for rigid ground motions along/about the mechanism axes;
* ``support_stiffness``: K_T condensed onto the payload's 6 DOF at O_C, nuts held;
* ``mount_buckling_factor``: the factor on the payload's weight at which the mount's
  tangent turns singular, from K_T(s) = K_0 + s (K_T(1) - K_0), s the weight factor
  (linearized buckling; K_0 the unloaded tangent);
* ``chain_end_reduction``: each chain Guyan-reduced onto its end nodes A and B (its
  four interior nodes condensed out of the segments' stiffness and mass);
* ``chain_buckling_factors``: each chain alone on its five segments, linearized the same
  way (the segments' co-rotational tangent at the state minus the unloaded one), end A
  clamped, end B either held (translations fixed, turning free) or free to sway
  laterally (turning held, as the payload frame holds it).

A prototype whose cuts are tied through section fields (``Prototype.chain_stiffness``, the
the provider fem; docs/meshing.md, "Session 24: the tied-cut frame") is assessed on what its
frame uses (``mechanism.frame_stiffness``, a ``CoupledStiffness``): its equilibrium, tangent
(the segments' blocks with the cross-segment blocks J_s^T K_st J_t; geometric stiffness per
segment from its share (K Xi)_s of the chain's wrench) and segment loads (the share again),
and each chain's linear stiffness on its section nodes J^T K_chain J (``chain_node_stiffness``)
instead of the sum of its segments' 12 x 12 (docs/structure.md, "Tied cuts").

Body-frame DOFs as in ``flexcal.validation.prototype.equilibrium``: translations then
rotations of each body in its own axes; the frame's axes are the mechanism axes at the
design pose. SI throughout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from flexcal.fem.eigen import buckling_modes, effective_modal_mass, natural_modes
from flexcal.fem.mass import box_inertia, rigid_body_mass
from flexcal.geometry.params import MechanismParams

from ..prototype.equilibrium import Loads, build_assembly, evaluate, node_poses, solve_equilibrium
from ..prototype.kinematics import se3_inverse
from ..prototype.mechanism import FRAME_BODY, N_CHAINS, N_SEGMENTS, NUT_BODIES, Prototype, frame_stiffness
from ..prototype.superelement import CoupledStiffness, segment_jacobian

__all__ = ["PAYLOAD_BOX", "NominalState", "nominal_state", "payload_mass_matrix", "assemble_segment_matrices",
           "mount_mass", "rigid_influence", "support_stiffness", "mount_modes", "MountModes",
           "mount_buckling_factor", "chain_buckling_factors", "chain_end_reduction", "chain_node_stiffness"]

PAYLOAD_BOX = (0.200, 1.400, 0.420)  # the reference mount's (MechanismParams.payload_box, a mount file's box_mm)
"""Sides [m] of the box the 300 kg payload fills (x along the grating normal, y along the
1400 mm side, z along the 420 mm side; DESIGN.md), centred on its centre of gravity."""


@dataclass(frozen=True, kw_only=True, eq=False)
class NominalState:
    """poses (n_bodies, 4, 4); tangent (n_dofs, n_dofs) [SI]; segment_gradient
    (n_segments, 12) [N, N m] (the load each segment carries at its nodes, node axes);
    tension (6,) [N] axial load of each chain, tension positive; weight_factor [-];
    commands (3,) [m] the actuator commands."""

    poses: np.ndarray
    tangent: np.ndarray
    segment_gradient: np.ndarray
    tension: np.ndarray
    weight_factor: float
    commands: np.ndarray


def nominal_state(prototype: Prototype, weight_factor: float = 1.0, *, commands: np.ndarray | None = None,
                  start: np.ndarray | None = None, extra_forces: tuple = ()) -> NominalState:
    """Equilibrium with the payload's weight times ``weight_factor`` at actuator
    ``commands`` (3,) [m] (default 0: the design commands; nuts at their transmissions'
    initial positions plus the command, no clearance or hysteresis), by Newton from
    ``start`` poses (default the design pose). ``extra_forces``: more dead loads
    ``(body, force (3,) [N] world, point (3,) [m] body frame)``."""
    mech = prototype.mechanism
    commands = np.zeros(3) if commands is None else np.asarray(commands, float)
    weight = weight_factor * mech.payload_mass * np.asarray(mech.gravity, float)
    springs = tuple((NUT_BODIES[i], float(mech.actuator_stiffness), placement.rotation[:, 0],
                     np.asarray(placement.point_a, float),
                     float(prototype.transmissions[i].initial_position + commands[i]))
                    for i, placement in enumerate(mech.driving_chains))
    loads = Loads(point_forces=((FRAME_BODY, weight, np.asarray(mech.centre_of_gravity, float)),) + tuple(extra_forces),
                  springs=springs)
    poses, info = solve_equilibrium(prototype.assembly, prototype.initial_poses if start is None else start,
                                    frame_stiffness(prototype, prototype.segment_stiffness), loads, prototype.settings,
                                    where=f"at commands {commands * 1e3} mm, weight x {weight_factor:g}")
    tension = -info.segment_gradient.reshape(N_CHAINS, N_SEGMENTS, 12)[:, 0, 0]
    return NominalState(poses=poses, tangent=info.tangent, segment_gradient=info.segment_gradient, tension=tension,
                        weight_factor=float(weight_factor), commands=commands.copy())


def payload_mass_matrix(mechanism: MechanismParams, box: tuple[float, float, float] | None = None) -> np.ndarray:
    """6 x 6 rigid-body mass [kg, kg m, kg m^2] of the payload at O_C, frame axes: its mass
    filling ``box`` (sides [m]; default ``mechanism.payload_box``) centred on its centre of
    gravity, or with ``mechanism.payload_inertia`` (principal moments [kg m^2]) when given."""
    m = mechanism.payload_mass
    if box is None and mechanism.payload_inertia is not None:
        inertia = np.diag(np.asarray(mechanism.payload_inertia, float))
    else:
        inertia = box_inertia(m, np.asarray(mechanism.payload_box if box is None else box, float))
    return rigid_body_mass(m, inertia, np.asarray(mechanism.centre_of_gravity, float), np.zeros(3))


def assemble_segment_matrices(prototype: Prototype, matrices: np.ndarray) -> np.ndarray:
    """Sum per-segment matrices (n_segments, 12, 12) (start node then end node, node axes)
    into the mount's DOFs (n_dofs, n_dofs) through the prototype's node maps (ground
    nodes drop out)."""
    a = prototype.assembly
    n, m, dofs = a.n_dofs, a.segment_map, a.segment_dofs
    local = np.swapaxes(m, -1, -2) @ np.asarray(matrices, float) @ m
    flat = dofs[:, :, None] * (n + 1) + dofs[:, None, :]
    total = np.bincount(flat.ravel(), weights=local.ravel(), minlength=(n + 1) ** 2)
    return total.reshape(n + 1, n + 1)[:n, :n]


def mount_mass(prototype: Prototype, segment_mass: np.ndarray, payload: np.ndarray) -> np.ndarray:
    """Mass matrix (n_dofs, n_dofs) of the mount: segments' masses (6, 5, 12, 12) and the
    payload's 6 x 6 at the frame's DOFs."""
    M = assemble_segment_matrices(prototype, np.asarray(segment_mass, float).reshape(-1, 12, 12))
    start = prototype.assembly.dof_start[FRAME_BODY]
    M[start:start + 6, start:start + 6] += payload
    return 0.5 * (M + M.T)


def rigid_influence(prototype: Prototype, poses: np.ndarray) -> np.ndarray:
    """(n_dofs, 6): the body DOFs of a rigid motion of everything (ground included)
    by a unit translation along x, y, z and a unit rotation about x, y, z through O_C
    (mechanism axes). A nut takes the component along its axis."""
    a = prototype.assembly
    out = np.zeros((a.n_dofs, 6))
    for body, selection in enumerate(a.body_selection):
        if selection.shape[1] == 0:
            continue
        R, p = poses[body, :3, :3], poses[body, :3, 3]
        twist = np.zeros((6, 6))  # body-frame twist of each unit world motion
        twist[:3, :3] = R.T
        twist[:3, 3:] = R.T @ np.array([np.cross(e, p) for e in np.eye(3)]).T
        twist[3:, 3:] = R.T
        start = a.dof_start[body]
        out[start:start + selection.shape[1]] = selection.T @ twist
    return out


def _schur(K: np.ndarray, keep: np.ndarray, drop: np.ndarray) -> np.ndarray:
    K_kd = K[np.ix_(keep, drop)]
    return K[np.ix_(keep, keep)] - K_kd @ np.linalg.solve(K[np.ix_(drop, drop)], K_kd.T)


def support_stiffness(prototype: Prototype, tangent: np.ndarray, *, nuts_held: bool = True) -> np.ndarray:
    """6 x 6 stiffness [N/m, N, N m/rad] of the mount at O_C (payload DOFs, frame axes):
    the tangent condensed onto the frame's DOFs, the nuts held (their DOFs fixed) or, with
    ``nuts_held=False``, on their actuator springs."""
    a = prototype.assembly
    frame = np.arange(a.dof_start[FRAME_BODY], a.dof_start[FRAME_BODY] + 6)
    nuts = np.array([a.dof_start[b] for b in NUT_BODIES])
    others = np.setdiff1d(np.arange(a.n_dofs), frame)
    if nuts_held:
        others = np.setdiff1d(others, nuts)
    K = 0.5 * (tangent + tangent.T)
    if nuts_held:
        keep = np.setdiff1d(np.arange(a.n_dofs), nuts)
        K = K[np.ix_(keep, keep)]
        frame = np.searchsorted(keep, frame)
        others = np.searchsorted(keep, others)
    return _schur(K, frame, others)


@dataclass(frozen=True, kw_only=True, eq=False)
class MountModes:
    """frequencies (n,) [Hz]; effective_mass (n, 6): [kg] for ground translations along
    x, y, z, [kg m^2] for rotations about x, y, z through O_C; total_mass (6,): what
    all modes together would add up to (r^T M r); modes (n_dofs, n) M-normalized."""

    frequencies: np.ndarray
    effective_mass: np.ndarray
    total_mass: np.ndarray
    modes: np.ndarray


def mount_modes(prototype: Prototype, state: NominalState, mass: np.ndarray, n_modes: int = 12) -> MountModes:
    """The lowest ``n_modes`` natural modes of the mount at ``state`` (tangent) with
    ``mass`` (n_dofs, n_dofs); actuator nuts on their springs."""
    K = sp.csr_matrix(0.5 * (state.tangent + state.tangent.T))
    M = sp.csr_matrix(mass)
    result = natural_modes(K, M, n_modes)
    r = rigid_influence(prototype, state.poses)
    return MountModes(frequencies=result.frequencies, effective_mass=effective_modal_mass(M, result.modes, r),
                      total_mass=np.einsum("ik,ij,jk->k", r, mass, r), modes=result.modes)


def mount_buckling_factor(unloaded: NominalState, loaded: NominalState) -> float:
    """Smallest positive s at which K_0 + s (K_T - K_0) / w is singular, times the
    loaded state's weight factor w: the factor on the nominal payload weight that buckles
    the mount, linearized about the unloaded state (module docstring)."""
    K0 = 0.5 * (unloaded.tangent + unloaded.tangent.T)
    dK = 0.5 * (loaded.tangent + loaded.tangent.T) - K0
    scale = loaded.weight_factor - unloaded.weight_factor
    return float(buckling_modes(sp.csr_matrix(K0), sp.csr_matrix(dK / scale), 6).factors[0]) + unloaded.weight_factor


def _chain_alone(prototype: Prototype, chain: int):
    """(assembly, stiffness) of chain ``chain`` alone: its six section nodes as free bodies
    (6 DOF each, node axes, identity offsets; DOFs 6 k .. 6 k + 5 of node k) joined by its five
    segments as the prototype's frame joins them (``frame_stiffness``: the K_jj, or the chain's
    K_chain with tied cuts)."""
    seg = np.arange(chain * N_SEGMENTS, (chain + 1) * N_SEGMENTS)
    assembly = build_assembly([np.eye(6)] * (N_SEGMENTS + 1), np.arange(N_SEGMENTS + 1),
                              np.broadcast_to(np.eye(4), (N_SEGMENTS + 1, 4, 4)),
                              np.c_[np.arange(N_SEGMENTS), np.arange(1, N_SEGMENTS + 1)],
                              prototype.assembly.segment_reference_inverse[seg])
    stiffness = frame_stiffness(prototype, prototype.segment_stiffness)
    if isinstance(stiffness, CoupledStiffness):
        return assembly, CoupledStiffness(blocks=stiffness.blocks[chain:chain + 1],
                                          segments=np.arange(N_SEGMENTS)[None])
    return assembly, stiffness[seg]


def _chain_matrices(prototype: Prototype, state: NominalState, chain: int) -> tuple[np.ndarray, np.ndarray]:
    """(K_0, dK) (36, 36) of chain ``chain`` alone on its six section nodes (node axes):
    the segments' unloaded tangent and the change of their tangent at ``state``
    (``_chain_alone``; the cross-segment blocks of a tied chain in both)."""
    assembly, stiffness = _chain_alone(prototype, chain)
    a = prototype.assembly
    nodes = node_poses(a, state.poses)
    ends = a.segment_nodes[chain * N_SEGMENTS:(chain + 1) * N_SEGMENTS]
    loaded_poses = np.concatenate([nodes[ends[:, 0]], nodes[ends[-1:, 1]]])
    unloaded_poses = np.broadcast_to(np.eye(4), (N_SEGMENTS + 1, 4, 4)).copy()
    for s in range(N_SEGMENTS):  # the undeformed chain, node 0 at the origin
        unloaded_poses[s + 1] = unloaded_poses[s] @ se3_inverse(assembly.segment_reference_inverse[s])
    step = prototype.settings.step
    loaded = evaluate(assembly, loaded_poses, stiffness, Loads(), True, step)[2]
    unloaded = evaluate(assembly, unloaded_poses, stiffness, Loads(), True, step)[2]
    return unloaded, loaded - unloaded


def chain_buckling_factors(prototype: Prototype, state: NominalState) -> dict[str, np.ndarray]:
    """Per chain (6,) factors on the loads it carries at ``state`` that make it buckle
    alone, for end B "held" (translations fixed, turning free) and "sway" (lateral
    translations free, turning fixed); end A clamped, B free along the chain in both.
    Linearized like the mount's: K_0 + s (K_T - K_0) singular, K_T the segments' tangent
    at the state (their geometric terms included). A chain in tension gets inf."""
    out = {"held": np.full(N_CHAINS, np.inf), "sway": np.full(N_CHAINS, np.inf)}
    interior = np.arange(6, 30)
    b = 30 + np.arange(6)
    free_b = {"held": b[[0, 3, 4, 5]], "sway": b[:3]}
    for c in range(N_CHAINS):
        if not state.tension[c] < 0:
            continue
        K0, dK = _chain_matrices(prototype, state, c)
        for case, extra in free_b.items():
            free = np.r_[interior, extra]
            try:
                result = buckling_modes(sp.csr_matrix(K0[np.ix_(free, free)]), sp.csr_matrix(dK[np.ix_(free, free)]), 4)
            except ValueError:  # no positive factor among the four largest: does not buckle this way
                continue
            out[case][c] = result.factors[0]
    return out


def chain_node_stiffness(prototype: Prototype, chain: int) -> np.ndarray:
    """(36, 36) [SI] linear stiffness of chain ``chain`` on its six section nodes (DOFs ux..rz
    of node 0 .. 5, node axes): its segments' 12 x 12 summed; with tied cuts J^T K_chain J, J
    (30, 36) the linear map of node motions to the segments' twists (xi_s = u_(s+1) - Ad(D_s)
    u_s, ``segment_jacobian`` at the undeformed pose), which is that sum when K_chain is the
    block diagonal of the segments' K_jj."""
    K = np.zeros((36, 36))
    if prototype.chain_stiffness is None:
        for s in range(N_SEGMENTS):
            dofs = np.arange(6 * s, 6 * s + 12)
            K[np.ix_(dofs, dofs)] += prototype.segment_stiffness_12[chain, s]
        return K
    D = prototype.assembly.segment_reference_inverse[chain * N_SEGMENTS:(chain + 1) * N_SEGMENTS]
    jacobian = segment_jacobian(se3_inverse(D), D)  # (5, 6, 12)
    J = np.zeros((6 * N_SEGMENTS, 36))
    for s in range(N_SEGMENTS):
        J[6 * s:6 * s + 6, 6 * s:6 * s + 12] = jacobian[s]
    K = J.T @ prototype.chain_stiffness[chain] @ J
    return 0.5 * (K + K.T)


def chain_end_reduction(prototype: Prototype, segment_mass: np.ndarray, chain: int) -> tuple[np.ndarray, np.ndarray]:
    """(K_c, M_c) (12, 12) of chain ``chain`` Guyan-reduced onto its end nodes A and B
    (DOFs ux..rz at A then B, chain axes, SI): the six section nodes joined by the
    chain's linear stiffness (``chain_node_stiffness``) and ``segment_mass`` (6, 5, 12, 12); the interior
    nodes follow statically, Psi = [I; -K_ii^-1 K_ie; I]. Exact at zero frequency: M_c
    keeps the chain's rigid-body mass."""
    K = chain_node_stiffness(prototype, chain)
    M = np.zeros((36, 36))
    for s in range(N_SEGMENTS):
        dofs = np.arange(6 * s, 6 * s + 12)
        M[np.ix_(dofs, dofs)] += segment_mass[chain, s]
    ends = np.r_[0:6, 30:36]
    interior = np.arange(6, 30)
    psi = np.zeros((36, 12))
    psi[ends, np.arange(12)] = 1.0
    psi[interior] = -np.linalg.solve(K[np.ix_(interior, interior)], K[np.ix_(interior, ends)])
    K_c, M_c = psi.T @ K @ psi, psi.T @ M @ psi
    return 0.5 * (K_c + K_c.T), 0.5 * (M_c + M_c.T)
