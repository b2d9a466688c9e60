"""Pictures and a VTU of the mount's mode shapes: the six chains as polylines through their
section nodes and the payload as its box, undeformed and displaced by a mode.

A mode phi (n_dofs) moves each body b by the body-frame twist (v, w) = S_b phi_b
(translations then rotations, ``prototype.equilibrium``); a point at o in the body's
frame moves by R_b (v + w x o) in the world (mechanism axes). The chain points are the
section nodes (ground nodes stay), the payload box (``MechanismParams.payload_box`` about the
centre of gravity) moves with the frame. Shapes are drawn with the largest point motion
scaled to ``SHAPE_SCALE`` of the mount's size; the VTU holds the unscaled motion of each
mode (M-normalized phi: m/sqrt(kg)) as point data "mode_k".
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from ..prototype.mechanism import FRAME_BODY, N_CHAINS, Prototype

__all__ = ["SHAPE_SCALE", "mode_points", "point_motion", "write_mode_pngs", "write_modes_vtu"]

SHAPE_SCALE = 0.08
"""Largest drawn motion as a fraction of the mount's largest extent (visible, not tangled)."""

_BOX_EDGES = [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)]


def mode_points(prototype: Prototype, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (36 + 8, 3) [m] world, owner body (44,), offset (44, 3) [m] in the owner's
    frame): the 6 x 6 chain section nodes (chain-major, A to B), then the payload box's 8
    corners (x slowest)."""
    a = prototype.assembly
    bodies = list(a.node_body[:6 * N_CHAINS])
    offsets = list(a.node_offset[:6 * N_CHAINS, :3, 3])
    centre = np.asarray(prototype.mechanism.centre_of_gravity, float)
    for signs in itertools.product((-0.5, 0.5), repeat=3):
        bodies.append(FRAME_BODY)
        offsets.append(centre + np.array(signs) * np.array(prototype.mechanism.payload_box))
    bodies, offsets = np.array(bodies), np.array(offsets)
    points = np.einsum("nij,nj->ni", poses[bodies, :3, :3], offsets) + poses[bodies, :3, 3]
    return points, bodies, offsets


def point_motion(prototype: Prototype, poses: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """(44, 3) world motion of the ``mode_points`` under DOF motion ``phi`` (n_dofs,)."""
    a = prototype.assembly
    _, bodies, offsets = mode_points(prototype, poses)
    out = np.zeros((len(bodies), 3))
    for k, (b, o) in enumerate(zip(bodies, offsets)):
        sel = a.body_selection[b]
        if sel.shape[1] == 0:
            continue
        twist = sel @ phi[a.dof_start[b]:a.dof_start[b] + sel.shape[1]]
        out[k] = poses[b, :3, :3] @ (twist[:3] + np.cross(twist[3:], o))
    return out


def _scale(points: np.ndarray, motion: np.ndarray) -> float:
    extent = np.ptp(points, axis=0).max()
    largest = np.linalg.norm(motion, axis=1).max()
    return SHAPE_SCALE * extent / largest if largest > 0 else 0.0


def write_mode_pngs(folder: Path, prototype: Prototype, poses: np.ndarray, modes: np.ndarray,
                    frequencies: np.ndarray, n: int = 6) -> list[str]:
    """mode_1.png .. mode_n.png in ``folder``: three views (x-y, x-z, y-z, mm) of the
    undeformed mount (grey) and the displaced one (chains blue/orange, box red). Returns
    the file names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    points, _, _ = mode_points(prototype, poses)
    names = []
    for k in range(min(n, modes.shape[1])):
        motion = point_motion(prototype, poses, modes[:, k])
        moved = points + _scale(points, motion) * motion
        fig, axes = plt.subplots(1, 3, figsize=(15, 5))
        for ax, (i, j) in zip(axes, [(0, 1), (0, 2), (1, 2)]):
            for shape, style in ((points, dict(color="0.7", lw=1)), (moved, None)):
                for c in range(N_CHAINS):
                    line = shape[6 * c:6 * c + 6] * 1e3
                    ax.plot(line[:, i], line[:, j], **(style or dict(color="tab:blue" if c < 3 else "tab:orange",
                                                                       lw=2, marker="o", ms=3)))
                box = shape[6 * N_CHAINS:] * 1e3
                for e0, e1 in _BOX_EDGES:
                    ax.plot(box[[e0, e1], i], box[[e0, e1], j], **(style or dict(color="tab:red", lw=1.5)))
            ax.set_xlabel("xyz"[i] + " [mm]")
            ax.set_ylabel("xyz"[j] + " [mm]")
            ax.set_aspect("equal")
            ax.grid(alpha=0.3)
        fig.suptitle(f"mode {k + 1}: {frequencies[k]:.1f} Hz (grey: undeformed; motion scaled to "
                     f"{100 * SHAPE_SCALE:g} % of the mount's size)")
        # fixed margins: tight_layout measured every tick label and took half of the pictures' CPU
        fig.subplots_adjust(left=0.06, right=0.99, bottom=0.11, top=0.88, wspace=0.32)
        name = f"mode_{k + 1}.png"
        fig.savefig(folder / name, dpi=90)
        plt.close(fig)
        names.append(name)
    return names


def write_modes_vtu(path: Path, prototype: Prototype, poses: np.ndarray, modes: np.ndarray,
                    frequencies: np.ndarray) -> None:
    """One VTU: chain polylines and the payload box (a hexahedron) at ``poses``, point
    data "mode_k" (44, 3) the motion of mode k [m/sqrt(kg)], field data "frequencies_Hz".
    Warp by a mode in ParaView to see it."""
    import pyvista as pv

    points, _, _ = mode_points(prototype, poses)
    cells, types = [], []
    for c in range(N_CHAINS):
        for s in range(5):
            cells += [2, 6 * c + s, 6 * c + s + 1]
            types.append(pv.CellType.LINE)
    box = 6 * N_CHAINS + np.array([0, 4, 6, 2, 1, 5, 7, 3])  # VTK hexahedron order from x-slowest corners
    cells += [8, *box.tolist()]
    types.append(pv.CellType.HEXAHEDRON)
    grid = pv.UnstructuredGrid(np.array(cells), np.array(types, np.uint8), points)
    for k in range(modes.shape[1]):
        grid.point_data[f"mode_{k + 1}"] = point_motion(prototype, poses, modes[:, k])
    grid.field_data["frequencies_Hz"] = np.asarray(frequencies, float)
    grid.save(str(path))
