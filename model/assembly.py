"""Paper Eq. 2-3: per-candidate assembly of the six chains in parallel at O_C.

Everything here depends only on the parameters, so it is computed once per candidate
(batched over candidates) and the per-point solve (``forward``) only does small products.

Chain i has stiffness ``K_i = C_B,i^-1`` (chain frame, at B, A clamped; driving chains
include the actuator spring). The frame twist ``X_C`` at O_C moves B by
``J_i X_C`` (chain frame), ``J_i = [[R^T, -R^T [p_B]x], [0, R^T]]``; the A end moves only
along the axis by ``u_i`` (actuator input + initial position + parasitic term + clearance),
which reaches B rigidly as ``u_i e_x``. The energy ``1/2 sum (J_i X_C - u_i e_x)^T K_i (...)``
gives the Eq. 3 blocks ``K_i-22 = J^T K J``, ``K_i-21 = -J^T K W`` and the equilibrium

    K_CC X_C = F_C + sum_i g_i u_i,   K_CC = sum_i J_i^T K_i J_i,   g_i = J_i^T K_i e_x,

with ``F_C`` the payload's weight moved to O_C (force m g, moment r_cg x m g). The axial
load of chain i (positive = tension) is ``N_i = e_x^T K_i (J_i X_C - u_i e_x)
= g_i^T X_C - k_i u_i``, ``k_i = K_i[0, 0]``.

Mount offsets (d, phi) of a load chain move its base point A by
``d (cos(phi) y0 + sin(phi) z0)`` (nominal local axes); the chain is built to fit the new
A-B distance (the strut absorbs it), so the unloaded pose stays zero.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from flexcal.geometry.frames import chain_rotation, frame_to_point_transform
from flexcal.geometry.params import MechanismParams

from . import kernel
from .chain import chain_compliance_entries, chain_entries_and_elements, stiffness_from_entries
from .consistent import shortening_matrices
from .second_order import preload_geometric_stiffness
from .parameters import CHAIN_NAMES, DIMENSION_SYMBOLS, DRIVING, LOAD, N_CHAINS, ParameterSpace

__all__ = ["MechanismMatrices", "mechanism_matrices", "payload_wrench"]

COMPILED_MIN_CANDIDATES = 32  # batches this large use the compiled linear algebra (tested equal)


@dataclass(frozen=True, kw_only=True)
class MechanismMatrices:
    """Per-candidate matrices of the model (leading axis = candidate, n_c).

    chain_stiffness K_i (n_c, 6, 6, 6) [SI stiffness, chain frame at B];
    frame_transform J_i (n_c, 6, 6, 6); rotation R_i (n_c, 6, 3, 3); point_a (n_c, 6, 3) [m];
    frame_stiffness K_CC (n_c, 6, 6); axial_gain G (n_c, 6, 6), column i = g_i [N/m, N];
    input_gain H = K_CC^-1 G (n_c, 6, 6), column i = dX_C/du_i [m/m, rad/m];
    gravity_pose X_g (n_c, 6) [m, rad]; gravity_loads N_g (n_c, 6) [N];
    coupling m_ij = g_i^T K_CC^-1 g_j (n_c, 6, 6) [N/m]; axial_stiffness k_i (n_c, 6) [N/m];
    load_gain dN/du = m - diag(k) (n_c, 6, 6) [N/m]; nut_stiffness s_i = k_i - m_ii of the
    driving chains (n_c, 3) [N/m]; parasitic_rows P (n_c, 12, 6): rows 0-5 the local-y
    displacement of each chain's B-side leaf-1 hinge, scaled by sqrt(L_d/L_y), rows 6-11
    the local-z displacement of its B-side leaf-2 hinge, scaled by sqrt(L_d/L_z), per unit X_C;
    parasitic_gain Q = P H (n_c, 12, 6); parasitic_gravity P X_g (n_c, 12) [m];
    parasitic_coefficient K_L = 1/(2 L_d) (n_c, 6) [1/m]; hysteresis mu (n_c, 3) [-];
    clearance CL (n_c, 3) [m]; initial_position x0 (n_c, 3) [m]; point_b (n_c, 6, 3) [m] the
    chains' frame-side ends; second_order (n_c,) bool: apply ``model.second_order`` (the
    frame stiffness then holds the preload P-delta); breakaway_band (n_c, 3) [m] the play
    band F_b / s_i of each nut (``ParameterSpace.breakaway_force``), -1 without play state;
    shortening S_j (n_c, 6, 6, 6) the chains' second-order shortening forms; lateral_defect L_j
    (n_c, 6, 5, 6, 6) their lateral compatibility defects (``shortening.chain_second_order_forms``;
    zero outside the consistent model); load_shortening T_j (n_c, 6, 6, 6) [1/(N m), 1/N, m/N] their
    load forms (the shortening under axial load N is ``D^T (S + N T) D``; zero outside the
    consistent model); consistent
    (n_c,) bool: solve with ``model.consistent`` (``ParameterSpace.chain_shortening``; the
    frame stiffness is then the linear one, the P-delta is in the fixed point); payload
    (n_c, 6) the weight [N] and its centre of gravity [m] (mechanism frame).
    """

    chain_stiffness: np.ndarray
    frame_transform: np.ndarray
    rotation: np.ndarray
    point_a: np.ndarray
    frame_stiffness: np.ndarray
    axial_gain: np.ndarray
    input_gain: np.ndarray
    gravity_pose: np.ndarray
    gravity_loads: np.ndarray
    coupling: np.ndarray
    axial_stiffness: np.ndarray
    load_gain: np.ndarray
    nut_stiffness: np.ndarray
    parasitic_rows: np.ndarray
    parasitic_gain: np.ndarray
    parasitic_gravity: np.ndarray
    parasitic_coefficient: np.ndarray
    mu: np.ndarray
    clearance: np.ndarray
    initial_position: np.ndarray
    point_b: np.ndarray
    second_order: np.ndarray
    breakaway_band: np.ndarray
    shortening: np.ndarray
    lateral_defect: np.ndarray
    load_shortening: np.ndarray
    consistent: np.ndarray
    payload: np.ndarray

    @property
    def n_candidates(self) -> int:
        return self.chain_stiffness.shape[0]


def payload_wrench(mech: MechanismParams) -> np.ndarray:
    """F_C (6,): the payload's weight moved to O_C, [N, N m] (force m g, moment r_cg x m g)."""
    force = mech.payload_mass * np.asarray(mech.gravity, dtype=float)
    return np.concatenate([force, np.cross(np.asarray(mech.centre_of_gravity, dtype=float), force)])


# valid values by symbol (every value finite; the symbols not named here > 0)
_RULES = {"a": "0 <= a <= l/2", "mu": "0 <= mu <= 1", "d": ">= 0", "CL": ">= 0", "phi": "finite", "x0": "finite"}


@functools.lru_cache(maxsize=16)
def _range_masks(names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n_params,) masks of the parameters that must be > 0, >= 0 and <= 1 (``_RULES``), by symbol."""
    symbol = np.array([name.split(".")[1] for name in names])
    positive = ~np.isin(symbol, tuple(_RULES))
    return positive, np.isin(symbol, ("a", "d", "mu", "CL")), symbol == "mu"


def _validate(values: np.ndarray, space: ParameterSpace, candidate_offset: int = 0) -> None:
    """Raise ``ValueError`` naming the first candidate and parameter with an invalid value."""
    positive, non_negative, at_most_one = _range_masks(space.all_names)
    fillet, length = space.chain_indices("a", "l").T
    with np.errstate(invalid="ignore"):
        problem = (~np.isfinite(values) | (positive & (values <= 0)) | (non_negative & (values < 0))
                   | (at_most_one & (values > 1)))
        problem[:, fillet] |= 2.0 * values[:, fillet] > values[:, length]
    if np.any(problem):
        cand, col = np.argwhere(problem)[0]
        name = space.all_names[col]
        rule = _RULES.get(name.split(".")[1], "> 0")
        raise ValueError(f"candidate {cand + candidate_offset}: parameter {name}={values[cand, col]!r} (SI) is invalid: "
                         f"must be finite and {rule}")


@functools.lru_cache(maxsize=16)
def _mechanism_constants(mech: MechanismParams) -> dict[str, np.ndarray]:
    """Arrays of the nominal design that every call needs (cached per mechanism)."""
    return {
        "point_a": np.array([c.point_a for c in mech.chains], dtype=float),
        "point_b": np.array([c.point_b for c in mech.chains], dtype=float),
        "roll": np.array([c.roll_reference for c in mech.chains], dtype=float),
        "rotation": np.array([c.rotation for c in mech.chains]),
        "section": np.array([c.chain.section for c in mech.chains]),
        "connector": np.array([c.chain.connector_length for c in mech.chains]),
        "end_block": np.array([c.chain.end_block_length for c in mech.chains]),
        "actuator": np.array([mech.actuator_stiffness if c.is_driving else np.inf for c in mech.chains]),
        "wrench": payload_wrench(mech),
    }


def _parasitic_rows(rotation, point_b, end_block, l, connector, length) -> np.ndarray:
    """(n_c, 12, 6): per chain the scaled lateral-displacement rows (y then z) of its B-side
    pivots under a frame twist X_C (Eq. 4-5 with per-direction pivots, docs/model.md)."""
    axis = rotation[..., :, 0]
    pivot_y = point_b - (end_block + 0.5 * l)[..., None] * axis
    pivot_z = point_b - (end_block + 1.5 * l + connector)[..., None] * axis
    pivot_distance = length - 2.0 * end_block - 2.0 * l - connector
    span_y = length - 2.0 * end_block - l
    span_z = length - 2.0 * end_block - 3.0 * l - 2.0 * connector
    # local-e displacement of point p under X_C = [d, theta]: e.(d + theta x p) = [e, p x e] . X_C
    y_axis, z_axis = rotation[..., :, 1], rotation[..., :, 2]
    rows_y = np.concatenate([y_axis, np.cross(pivot_y, y_axis)], axis=-1) * np.sqrt(pivot_distance / span_y)[..., None]
    rows_z = np.concatenate([z_axis, np.cross(pivot_z, z_axis)], axis=-1) * np.sqrt(pivot_distance / span_z)[..., None]
    return np.concatenate([rows_y, rows_z], axis=1)


def mechanism_matrices(values, space: ParameterSpace, *, candidate_offset: int = 0,
                       n_threads: int = 1) -> MechanismMatrices:
    """Per-candidate matrices for parameter vectors ``values`` (n_c, 45) or (45,) [SI].

    ``space`` supplies the nominal mechanism (points, material, payload, actuators).
    The chain and frame formulas run compiled from ``chain.COMPILED_MIN_CHAINS`` and
    ``COMPILED_MIN_CANDIDATES`` on, numpy below; the consistent model's
    (``space.chain_shortening``, whose solve runs compiled only) at every batch size: a
    least-squares residual's single candidate spent ~3/4 of its call in numpy's per-call
    overhead (docs/model.md 10, "Session 34"). Raises ``ValueError`` naming the candidate
    (index + ``candidate_offset``) and parameter for invalid values, or a chain whose
    dimensions leave no strut. ``n_threads``: the consistent model's chain kernels split their
    chains over that many threads (each chain's bits as on one).
    """
    values = np.atleast_2d(np.asarray(values, dtype=float))
    if values.ndim != 2 or values.shape[1] != len(space.parameters):
        raise ValueError(f"parameter values must have shape (n_candidates, {len(space.parameters)}) with all "
                         f"parameters (use ParameterSpace.full_values for a subset), got {values.shape}")
    _validate(values, space, candidate_offset)
    mech = space.mechanism
    n_c = values.shape[0]
    # (n_c, chains, symbols) -> one (n_c, chains) array per symbol
    w, a, l, t1, t2 = values[:, space.chain_indices("w", "a", "l", "t1", "t2")].transpose(2, 0, 1)
    fixed = _mechanism_constants(mech)
    point_a0, point_b, roll, nominal_rotation = fixed["point_a"], fixed["point_b"], fixed["roll"], fixed["rotation"]
    section, connector, end_block, actuator = fixed["section"], fixed["connector"], fixed["end_block"], fixed["actuator"]
    offset = np.zeros((n_c, N_CHAINS, 3))
    d, phi = values[:, space.chain_indices("d", "phi")].transpose(2, 0, 1)  # (n_c, 3): the load chains
    offset[:, LOAD] = d[..., None] * (np.cos(phi)[..., None] * nominal_rotation[LOAD, :, 1]
                                       + np.sin(phi)[..., None] * nominal_rotation[LOAD, :, 2])
    point_a = point_a0 + offset
    rotation = chain_rotation(point_a, point_b, roll)
    length = np.linalg.norm(point_b - point_a, axis=-1)
    strut = length - 2.0 * end_block - 4.0 * l - 2.0 * connector
    if np.any(strut <= 0):
        cand, chain = np.argwhere(strut <= 0)[0]
        raise ValueError(f"candidate {cand + candidate_offset}: chain {CHAIN_NAMES[chain]} has no strut left (hinge length "
                         f"l={l[cand, chain] * 1e3:.4g} mm too long for the chain length {length[cand, chain] * 1e3:.4g} mm)")
    # the consistent model runs compiled (its play state and solve), so its set-up does too:
    # one kernel pass gives the chains' entries and the shortening's elements
    consistent = bool(space.chain_shortening) and kernel.available()
    elements = None
    if consistent:
        compliance, *elements = chain_entries_and_elements(length, l, w, a, t1, t2, section=section,
                                                           connector_length=connector, end_block_length=end_block,
                                                           material=mech.material, n_threads=n_threads)
    else:
        compliance = chain_compliance_entries(length, l, w, a, t1, t2, section=section, connector_length=connector,
                                              end_block_length=end_block, material=mech.material)
    if space.compliance_factors:  # measured correction of the closed-form chains (docs/model.md 7)
        factors = np.asarray(space.compliance_factors, dtype=float)
        if space.compliance_slopes:  # the factors follow the dimensions (slopes measured at nominal)
            nominal = space.nominal_full[space.chain_indices(*DIMENSION_SYMBOLS)]  # (chains, 5)
            relative = np.stack([w, a, l, t1, t2], axis=-1) / nominal - 1.0
            slopes = np.reshape(space.compliance_slopes, (N_CHAINS, len(DIMENSION_SYMBOLS), 8))
            factors = factors + np.einsum("cjk,jke->cje", relative, slopes)
            if space.compliance_curvatures:  # and to second order (docs/model.md 11, session 18)
                curvatures = np.reshape(space.compliance_curvatures, (N_CHAINS, len(DIMENSION_SYMBOLS),
                                                                      len(DIMENSION_SYMBOLS), 8))
                factors = factors + 0.5 * np.einsum("cjk,cjm,jkme->cje", relative, relative, curvatures)
            if np.any(factors <= 0):
                cand = int(np.argwhere(factors <= 0)[0, 0])
                raise ValueError(f"candidate {cand + candidate_offset}: a chain-compliance factor came out <= 0 from "
                                 "compliance_slopes; the dimensions are too far from nominal for the correction")
        compliance = {key: entry * factors[..., i] for i, (key, entry) in enumerate(compliance.items())}
    compliance["ux_Fx"] = compliance["ux_Fx"] + 1.0 / actuator  # actuator spring in series (1/inf = 0 for loads)
    stiffness = stiffness_from_entries(compliance)
    # (the compiled kernel also returns parasitic rows of one centre point; they are
    # replaced below by the per-direction pivots)
    centre_distance = end_block + l + 0.5 * connector
    centre = point_b - centre_distance[..., None] * rotation[..., :, 0]
    if consistent or (n_c >= COMPILED_MIN_CANDIDATES and kernel.available()):
        linear = kernel.assemble_compiled(stiffness, rotation, point_b, centre, fixed["wrench"])
        if not np.all(np.isfinite(linear["gravity_pose"])):
            cand = int(np.argwhere(~np.all(np.isfinite(linear["gravity_pose"]), axis=1))[0, 0])
            raise ValueError(f"candidate {cand + candidate_offset}: the frame stiffness is not positive definite; "
                             f"the mechanism is singular for these parameters")
        transform, frame_stiffness, axial_gain = linear["frame_transform"], linear["frame_stiffness"], linear["axial_gain"]
        input_gain, gravity_pose = linear["input_gain"], linear["gravity_pose"]
    else:
        transform = frame_to_point_transform(rotation, point_b)
        transform_t = np.swapaxes(transform, -1, -2)
        frame_stiffness = np.sum(transform_t @ stiffness @ transform, axis=1)
        axial_gain = np.swapaxes((transform_t @ stiffness[..., :, :1])[..., 0], -1, -2)  # (n_c, 6 dof, 6 chains)
        rhs = np.concatenate([axial_gain, np.broadcast_to(fixed["wrench"][:, None], (n_c, 6, 1))], axis=-1)
        solved = np.linalg.solve(frame_stiffness, rhs)
        input_gain, gravity_pose = solved[..., :6], solved[..., 6]
    if space.second_order and not space.chain_shortening:
        # the chains' weight preload tilts with their swing: P-delta stiffness (model.second_order)
        rows = _parasitic_rows(rotation, point_b, end_block, l, connector, length)
        pivot = length - 2.0 * end_block - 2.0 * l - connector
        rhs = np.concatenate([axial_gain, np.broadcast_to(fixed["wrench"][:, None], (n_c, 6, 1))], axis=-1)
        linear_stiffness = frame_stiffness
        for _ in range(3):  # the preload depends on the stiffness: fixed point, converged to ~1e-6 relative
            preload = np.einsum("cdi,cd->ci", axial_gain, gravity_pose)  # (n_c, 6) [N], tension +
            frame_stiffness = linear_stiffness + preload_geometric_stiffness(preload, rows, pivot)
            solved = np.linalg.solve(frame_stiffness, rhs)
            input_gain, gravity_pose = solved[..., :6], solved[..., 6]
    # Eq. 4-5 with the paper's "distance between the corresponding flexure hinges": a
    # local-y swing turns the strut about its two leaf-1 hinges (thin in y), a local-z
    # swing about its two leaf-2 hinges, so each direction has its own pivot pair (the
    # paper's points C4 and C3). The rows give the B-side pivot's lateral displacement,
    # scaled by sqrt(L_d / L_y) and sqrt(L_d / L_z) so that one K_L = 1/(2 L_d) per chain
    # yields r = -(dy^2 / (2 L_y) + dz^2 / (2 L_z)). See docs/model.md.
    pivot_distance = length - 2.0 * end_block - 2.0 * l - connector
    parasitic_rows = _parasitic_rows(rotation, point_b, end_block, l, connector, length)
    parasitic_gain = parasitic_rows @ input_gain
    parasitic_gravity = np.einsum("ckd,cd->ck", parasitic_rows, gravity_pose)
    coupling = np.swapaxes(axial_gain, -1, -2) @ input_gain
    axial_stiffness = stiffness[..., 0, 0]
    load_gain = coupling - axial_stiffness[:, :, None] * np.eye(N_CHAINS)
    nut = axial_stiffness[:, DRIVING] - np.diagonal(coupling, axis1=1, axis2=2)[:, DRIVING]
    if np.any(nut <= 0):
        cand, chain = np.argwhere(nut <= 0)[0]
        raise ValueError(f"candidate {cand + candidate_offset}: driving chain {CHAIN_NAMES[DRIVING][chain]} has no "
                         f"stiffness of its own (s = {nut[cand, chain]:.3g} N/m); the mechanism is singular for these "
                         f"parameters")
    mu, clearance, initial_position = values[:, space.chain_indices("mu", "CL", "x0")].transpose(2, 0, 1)  # drives
    if space.chain_shortening:
        correction = np.reshape(space.chain_shortening, (N_CHAINS, 6, 6))
        if space.shortening_slopes:  # the correction follows the dimensions (docs/model.md 11, session 18)
            nominal = space.nominal_full[space.chain_indices(*DIMENSION_SYMBOLS)]  # (chains, 5)
            relative = np.stack([w, a, l, t1, t2], axis=-1) / nominal - 1.0
            correction = correction + np.einsum(
                "cjk,jkab->cjab", relative, np.reshape(space.shortening_slopes, (N_CHAINS, len(DIMENSION_SYMBOLS), 6, 6)))
        shortening, lateral_defect, load_shortening = shortening_matrices(
            correction, length, l, w, a, t1, t2, section=section,
            connector_length=connector, end_block_length=end_block, material=mech.material, elements=elements,
            n_threads=n_threads)
    else:
        shortening, load_shortening = np.zeros((n_c, N_CHAINS, 6, 6)), np.zeros((n_c, N_CHAINS, 6, 6))
        lateral_defect = np.zeros((n_c, N_CHAINS, 5, 6, 6))
    return MechanismMatrices(
        chain_stiffness=stiffness, frame_transform=transform, rotation=rotation, point_a=point_a,
        frame_stiffness=frame_stiffness, axial_gain=axial_gain, input_gain=input_gain, gravity_pose=gravity_pose,
        gravity_loads=np.einsum("cdi,cd->ci", axial_gain, gravity_pose), coupling=coupling,
        axial_stiffness=axial_stiffness, load_gain=load_gain, nut_stiffness=nut,
        parasitic_rows=parasitic_rows, parasitic_gain=parasitic_gain, parasitic_gravity=parasitic_gravity,
        parasitic_coefficient=0.5 / pivot_distance,
        mu=mu.copy(), clearance=clearance.copy(), initial_position=initial_position.copy(),
        point_b=np.broadcast_to(point_b, (n_c,) + point_b.shape).copy(),
        second_order=np.full(n_c, bool(space.second_order)),
        breakaway_band=(np.full((n_c, 3), -1.0) if space.breakaway_force is None
                        else float(space.breakaway_force) / nut),
        shortening=shortening, lateral_defect=lateral_defect, load_shortening=load_shortening,
        consistent=np.full(n_c, bool(space.chain_shortening)),
        payload=np.broadcast_to(np.r_[mech.payload_mass * np.asarray(mech.gravity, dtype=float),
                                      np.asarray(mech.centre_of_gravity, dtype=float)], (n_c, 6)).copy(),
    )
