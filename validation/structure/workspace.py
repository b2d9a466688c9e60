"""Stress and stiffness of the mount over its workspace, and each actuator's stress-limited stroke.

The workspace is the box +-1 mrad theta_x, +-5 mrad theta_y, +-3 mrad theta_z
(``flexcal.model.trajectory.WORKSPACE``) counted from the zero-command pose. Its eight
corners are reached on the virtual prototype itself: commands x solve
theta(x) = theta(0) + corner, theta the rotation vector of the payload frame at the
prototype's equilibrium (payload weight, nuts on their springs), by the fixed-point
iteration x <- x + G^-1 (target - theta(x)) with G the nominal linear model's angle gain
(``model.assembly``); it converges because the prototype is close to that model (each
step cuts the error by ~40; stopped at ``ANGLE_TOL``).

At each state the peak von Mises stress of every chain is located: by beam theory at the
ends of the leaves' thin parts (``stress.chain_leaf_stresses``), and with FEM segments at
the mesh node of the largest nodal stress, named by the piece of the chain it lies in
(``locate``: leaf k from end A, its fillet on the A or B side or its thin part).

``stroke_limit`` bisects an actuator's command (the others at zero, one direction) for
the stroke at which the largest peak stress over all chains reaches a limit.
SI throughout.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Callable

import numpy as np

from flexcal.geometry.params import FlexureChain
from flexcal.model.trajectory import WORKSPACE

from ..prototype.kinematics import so3_log
from ..prototype.mechanism import FRAME_BODY, N_CHAINS, N_SEGMENTS, Prototype
from .mount import NominalState, nominal_state

__all__ = ["ANGLE_TOL", "workspace_corners", "frame_angles", "angle_gain", "commands_for_angles", "locate",
           "StressAt", "stress_at", "stroke_limit"]

ANGLE_TOL = 1e-8
"""[rad] corner angles reached to this (1e-5 of the smallest half-range: far below what
changes a stress figure; each iteration step gains ~40x, so ~4 steps)."""


def workspace_corners(mechanism=None) -> np.ndarray:
    """(8, 3) [rad] the corners of ``mechanism``'s workspace (``MechanismParams.workspace``;
    the reference mount's (+-1, +-5, +-3) mrad by default), theta_x slowest."""
    half_ranges = WORKSPACE if mechanism is None else mechanism.workspace
    return np.array(list(itertools.product(*[(-w, w) for w in half_ranges])))


def frame_angles(state: NominalState) -> np.ndarray:
    """(3,) [rad] rotation vector of the payload frame at ``state`` (design pose = 0)."""
    return so3_log(state.poses[FRAME_BODY, :3, :3])


def angle_gain(prototype: Prototype) -> np.ndarray:
    """(3 angles, 3 actuators) [rad/m] the nominal linear model's d theta / d x."""
    from flexcal.model.assembly import mechanism_matrices
    from flexcal.model.parameters import parameter_space

    space = parameter_space(prototype.mechanism)
    return mechanism_matrices(space.nominal_full, space).input_gain[0, 3:, 3:]


def commands_for_angles(prototype: Prototype, targets: np.ndarray, *, max_iter: int = 20
                        ) -> tuple[np.ndarray, list[NominalState]]:
    """(commands (n, 3) [m], states) putting the payload frame at ``targets`` (n, 3) [rad]
    from the zero-command pose (module docstring). Raises ``RuntimeError`` naming the
    target if the iteration does not reach ``ANGLE_TOL`` in ``max_iter`` steps."""
    G = angle_gain(prototype)
    zero = nominal_state(prototype)
    theta0 = frame_angles(zero)
    commands, states = [], []
    for target in np.atleast_2d(targets):
        x = np.linalg.solve(G, target)
        poses = zero.poses
        for _ in range(max_iter):
            state = nominal_state(prototype, commands=x, start=poses)
            poses = state.poses
            error = theta0 + target - frame_angles(state)
            if np.max(np.abs(error)) <= ANGLE_TOL:
                break
            x = x + np.linalg.solve(G, error)
        else:
            raise RuntimeError(f"the prototype did not reach the angles {target * 1e3} mrad in {max_iter} steps "
                               f"(error {error * 1e6} urad): raise max_iter or check the angle gain")
        commands.append(x)
        states.append(state)
    return np.array(commands), states


def locate(chain: FlexureChain, x: float) -> str:
    """Name of the piece of ``chain`` at local x [m]: "leaf k (A fillet | thin | B fillet)"
    for the k-th leaf from end A (its fillets: the first and last ``chain.fillet`` of the
    leaf), else the rigid piece ("block", "connector", "strut")."""
    leaf = 0
    for kind, a, b in chain.segments():
        if kind.startswith("leaf"):
            leaf += 1
        if a - 1e-9 <= x <= b + 1e-9:
            if not kind.startswith("leaf"):
                return kind
            zone = "A fillet" if x < a + chain.fillet else "B fillet" if x > b - chain.fillet else "thin part"
            return f"leaf {leaf} ({zone})"
    return "outside"


@dataclass(frozen=True, kw_only=True)
class StressAt:
    """Peak von Mises stress per chain at one state: beam (6,) [Pa] and beam_where (6,)
    labels; fem (6,) [Pa] and fem_where (6,) labels with x [mm], or None."""

    beam: np.ndarray
    beam_where: tuple[str, ...]
    fem: np.ndarray | None = None
    fem_where: tuple[str, ...] | None = None

    @property
    def governing(self) -> np.ndarray:
        """(6,) [Pa] the FEM figure where there is one, else the beam bound."""
        return self.fem if self.fem is not None else self.beam


def stress_at(prototype: Prototype, state: NominalState, fem=None, chains=None) -> StressAt:
    """Peak stresses and where they sit (``StressAt``) at ``state``; ``fem`` a
    ``FemSegments`` or None (beam bound only); ``chains``: indices of the chains the FEM
    figure is taken for (default all; the others get NaN and "")."""
    from .fem_segments import stress_twists
    from .stress import chain_leaf_stresses

    values, labels = chain_leaf_stresses(prototype, state.segment_gradient)
    k = np.argmax(values, axis=1)
    beam = values[np.arange(N_CHAINS), k]
    beam_where = tuple(labels[c][k[c]] for c in range(N_CHAINS))
    if fem is None:
        return StressAt(beam=beam, beam_where=beam_where)
    xi = stress_twists(prototype, state.poses, fem)
    peak, where = np.full(N_CHAINS, np.nan), []
    for c, placement in enumerate(prototype.mechanism.chains):
        if chains is not None and c not in chains:
            where.append("")
            continue
        xs, best = prototype.section_x[c], (-1.0, "")
        for s in range(N_SEGMENTS):
            value, point = fem.peak_von_mises_at(placement.chain, xs[s], xs[s + 1], np.r_[np.zeros(6), xi[c, s]])
            if value > best[0]:
                best = (value, f"segment {s + 1}, {locate(placement.chain, point[0])}, x = {point[0] * 1e3:.2f} mm")
        peak[c] = best[0]
        where.append(best[1])
    return StressAt(beam=beam, beam_where=beam_where, fem=peak, fem_where=tuple(where))


def stroke_limit(prototype: Prototype, actuator: int, sign: float, limit: float,
                 peak: Callable[[NominalState], float], *, start: float = 0.5e-3, rel_tol: float = 5e-3,
                 max_stroke: float = 20e-3) -> float:
    """The command [m] (>= 0, along ``sign``) of actuator ``actuator`` (0..2), the others
    at zero, at which ``peak(state)`` (the largest stress over the chains [Pa]) reaches
    ``limit`` [Pa]: bracketed by doubling from ``start`` and bisected to ``rel_tol`` of
    the stroke (stress grows with the stroke away from the gravity preload). Returns 0
    if the nominal state already exceeds it and ``inf`` beyond ``max_stroke``."""
    solved: dict[float, np.ndarray] = {}  # stroke -> poses: Newton starts from the nearest solved state

    def state_at(stroke):
        commands = np.zeros(3)
        commands[actuator] = sign * stroke
        start = solved[min(solved, key=lambda s: abs(s - stroke))] if solved else None
        state = nominal_state(prototype, commands=commands, start=start)
        solved[stroke] = state.poses
        return state

    if peak(state_at(0.0)) >= limit:
        return 0.0
    low, high = 0.0, start
    while peak(state_at(high)) < limit:
        low, high = high, 2.0 * high
        if high > max_stroke:
            return float("inf")
    while high - low > rel_tol * high:
        middle = 0.5 * (low + high)
        if peak(state_at(middle)) < limit:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high)
