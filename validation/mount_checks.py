"""Checks of a mount before any computation: is it held, can it reach its workspace, do its
load chains form one remote centre. ``flexcal.geometry.mount`` already refused impossible
dimensions while reading; these need the model's kinematics, so they live here.

``check_mount`` raises ``ValueError`` (one line: the CLI exits 2) for two bodies whose
solids overlap (two chains, or a chain and the payload's box when the file places it:
``flexcal.validation.mount_solids``, CadQuery booleans), a mount that is not held in every
direction by its chains' axes, or whose actuators' stroke cannot reach the workspace; it
returns warnings (lines) for a remote centre that the load chains' axes miss.
``read_checked_mount`` reads a mount file and checks it (``--mount FILE``).
"""

from __future__ import annotations

import itertools
import logging
import os

import numpy as np

from flexcal.geometry.params import MechanismParams

__all__ = ["check_mount", "read_checked_mount", "free_twist", "remote_centre", "required_travel",
           "MIN_CONSTRAINT", "MAX_CENTRE_MISS"]

# The smallest singular value of the chains' axis lines (unit wrenches, moments over the
# mount's size) relative to the largest, below which a direction is held by nothing but the
# flexures' bending: a designed-singular layout gives ~1e-16 (rounding); 1e-6 is far above
# rounding and far below any held layout (the reference mount: 0.10).
MIN_CONSTRAINT = 1e-6
# A miss of the load chains' axes up to 0.1 mm is a twentieth of the paper's 2 mm assembly
# offset range (the identified offsets absorb it); beyond it the remote centre is not sharp.
MAX_CENTRE_MISS = 1e-4  # [m]
_DIRECTIONS = ("translation along x", "translation along y", "translation along z", "rotation about x (theta_x)",
               "rotation about y (theta_y)", "rotation about z (theta_z)")


def _axis_lines(mechanism: MechanismParams) -> tuple[np.ndarray, float]:
    """((6, n_chains) unit wrenches [u; (r x u)/size] along the chains' axes, size [m])."""
    ends = np.array([[p.point_a, p.point_b] for p in mechanism.chains], dtype=float)
    size = float(np.max(np.linalg.norm(ends, axis=-1)))
    axis = ends[:, 1] - ends[:, 0]
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    return np.concatenate([axis.T, np.cross(ends[:, 1], axis).T / size]), size


def free_twist(mechanism: MechanismParams) -> tuple[float, np.ndarray]:
    """(relative smallest singular value of the chains' axis lines [-], the twist (6,)
    (translation [-], rotation times the mount's size [-]) that no chain axis resists)."""
    lines, _ = _axis_lines(mechanism)
    left, singular, _ = np.linalg.svd(lines)
    return float(singular[-1] / singular[0]), left[:, -1]


def _twist_words(twist: np.ndarray) -> str:
    k = int(np.argmax(np.abs(twist)))
    if abs(twist[k]) > 0.99:  # within ~8 deg of one axis of the frame
        return _DIRECTIONS[k]
    parts = ", ".join(f"{v:+.2f}" for v in twist)
    return f"the twist (vx, vy, vz, wx*size, wy*size, wz*size) = ({parts})"


def remote_centre(mechanism: MechanismParams) -> tuple[np.ndarray, float]:
    """(the point nearest to the three load chains' axes [m], the largest distance of an
    axis from it [m]): least squares over the lines."""
    normal_sum, rhs = np.zeros((3, 3)), np.zeros(3)
    lines = []
    for placement in mechanism.load_chains:
        a, b = np.asarray(placement.point_a, float), np.asarray(placement.point_b, float)
        u = (b - a) / np.linalg.norm(b - a)
        projector = np.eye(3) - np.outer(u, u)
        normal_sum += projector
        rhs += projector @ a
        lines.append((a, projector))
    centre = np.linalg.lstsq(normal_sum, rhs, rcond=None)[0]
    miss = max(float(np.linalg.norm(projector @ (centre - a))) for a, projector in lines)
    return centre, miss


def required_travel(mechanism: MechanismParams) -> np.ndarray:
    """(3,) [m] the travel each actuator needs for the corners of the workspace (nominal,
    small-deflection gain from the zero-command pose) plus its initial position and
    clearance ranges; ``inf`` where the gain cannot reach the angles at all."""
    from flexcal.model.assembly import mechanism_matrices
    from flexcal.model.parameters import parameter_space

    space = parameter_space(mechanism)
    gain = mechanism_matrices(space.nominal_full, space).input_gain[0, 3:, 3:]  # d theta / d x [rad/m]
    corners = np.array(list(itertools.product(*[(-w, w) for w in mechanism.workspace])))
    if np.linalg.cond(gain) > 1e12:  # the angles do not depend on the inputs independently
        return np.full(3, np.inf)
    inputs = np.linalg.solve(gain, corners.T).T
    errors = mechanism.errors
    return np.max(np.abs(inputs), axis=0) + max(abs(v) for v in errors.initial_position) + errors.clearance[1]


def check_mount(mechanism: MechanismParams, *, source: str = "mount") -> list[str]:
    """Refuse (``ValueError``, one line naming ``source``) a mount with two bodies whose
    solids overlap (``mount_solids.overlaps``), a direction of its pose free, or a stroke
    that cannot reach its workspace; the warnings (lines) of a remote centre the load
    chains' axes miss by more than ``MAX_CENTRE_MISS``."""
    from .mount_solids import PAYLOAD, overlaps

    collisions = overlaps(mechanism)
    if collisions:
        hit = collisions[0]
        bodies = f"chain {hit.first} runs into the payload" if hit.second == PAYLOAD else \
            f"chains {hit.first} and {hit.second} collide"
        raise ValueError(f"{source}: {bodies}: their solids overlap by {hit.volume * 1e9:.4g} mm^3 around "
                         f"({', '.join(f'{v * 1e3:.1f}' for v in hit.centre)}) mm; move one"
                         + (" or the payload's box_centre_mm" if hit.second == PAYLOAD else ""))
    ratio, twist = free_twist(mechanism)
    if ratio < MIN_CONSTRAINT:
        raise ValueError(f"{source}: the mount is not held in {_twist_words(twist)}: no chain's axis resists it "
                         f"(only the flexures' bending would); move or turn a chain so that the six axes hold "
                         f"every direction")
    travel = required_travel(mechanism)
    short = np.flatnonzero(travel > mechanism.actuator_half_stroke)
    if short.size:
        i = int(short[0])
        need = "cannot reach the workspace at all" if not np.isfinite(travel[i]) else \
            f"needs {travel[i] * 1e3:.3g} mm"
        raise ValueError(f"{source}: D{i + 1} {need} (workspace corners +-{', '.join(f'{w * 1e3:g}' for w in mechanism.workspace)} "
                         f"mrad plus the x0 and clearance ranges), more than half_stroke_mm = "
                         f"{mechanism.actuator_half_stroke * 1e3:g}; raise the stroke or shrink [workspace]")
    centre, miss = remote_centre(mechanism)
    if miss > MAX_CENTRE_MISS:
        return [f"{source}: the load chains' axes miss one remote centre by up to {miss * 1e3:.3g} mm (nearest "
                f"point ({', '.join(f'{v * 1e3:.1f}' for v in centre)}) mm); the remote centre is not sharp"]
    return []


def read_checked_mount(path: str | os.PathLike) -> MechanismParams:
    """The mount file at ``path`` read (``flexcal.geometry.mount.read_mount``) and checked
    (``check_mount``; its warnings logged)."""
    from flexcal.geometry.mount import read_mount

    mechanism = read_mount(path)
    for line in check_mount(mechanism, source=str(path)):
        logging.getLogger("flexcal.mount").warning("%s", line)
    return mechanism
