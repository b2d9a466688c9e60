"""Paper Eq. 1, written once: the compliance of elements in series, moved to one output point.

``C_out = sum_i T_i C_i T_i^T`` with the adjoint ``T_i = [[R_i, [r_i]x R_i], [0, R_i]]``,
``r_i = p_i - p_out`` (``geometry.frames.twist_transform``): element i is clamped at its
A-side end and loaded at ``p_i`` (its B-side end), with local axes ``R_i``.

``serial_compliance`` is the equation for any axes and points (hinge parts, a provider's
segments, a chain's nine elements). Every chain is a special case: elements whose axes are
the output's or turned a quarter about x, their loaded ends on the output's x axis. Then
``T_i C_i T_i^T`` closes on the eight independent entries (``hinge.ENTRY_INDEX`` order:
ux_Fx, uy_Fy, uy_Mz, rz_Mz, uz_Fz, uz_My, ry_My, rx_Mx): ``quarter_turn`` and
``moved_along_axis``. They are plain arithmetic on indexable entries, so the same two
functions run on numpy batches (``serial_entries_along_axis``) and, compiled by numba, inside
the chain kernel (``_numba_kernels.chain_entries``); tests/test_model_chain.py holds the
eight-entry sum equal to ``serial_compliance``.
"""

from __future__ import annotations

import numpy as np

from flexcal.geometry.frames import twist_transform

__all__ = ["serial_compliance", "serial_entries_along_axis", "moved_along_axis", "quarter_turn"]


def serial_compliance(element_compliance: np.ndarray, element_rotation: np.ndarray, element_point: np.ndarray,
                      output_point: np.ndarray) -> np.ndarray:
    """Eq. 1: compliance (..., 6, 6) at ``output_point`` of elements in series.

    element_compliance (..., n, 6, 6) at each element's loaded end in its own axes;
    element_rotation (..., n, 3, 3) its axes (columns) in the output frame; element_point
    (..., n, 3) [m] its loaded end; output_point (..., 3) [m].
    """
    offset = np.asarray(element_point, dtype=float) - np.asarray(output_point, dtype=float)[..., None, :]
    transform = twist_transform(element_rotation, offset)
    return np.sum(transform @ element_compliance @ np.swapaxes(transform, -1, -2), axis=-3)


def moved_along_axis(e, d):
    """One term ``T C T^T`` of Eq. 1 on the eight entries, ``T = twist_transform(I, [d, 0, 0])``.

    e: the eight entries (indexable: floats, or arrays of one shape); d [m]: the loaded end's
    x minus the output's. uy' = uy - d rz and uz' = uz + d ry, so the (uy, rz) block becomes
    [[a - 2 d b + d^2 c, b - d c], [., c]] and the (uz, ry) block the same with +d; ux and rx
    do not move. Returns a tuple of eight.
    """
    return (e[0], e[1] - 2.0 * d * e[2] + d * d * e[3], e[2] - d * e[3], e[3],
            e[4] + 2.0 * d * e[5] + d * d * e[6], e[5] + d * e[6], e[6], e[7])


def quarter_turn(e):
    """The eight entries of an element turned +90 deg about x (``chain.LEAF2_ROTATION``):
    element y -> output z, element z -> output -y, so the (uy, rz) and (uz, ry) blocks swap
    and their couplings change sign. Returns a tuple of eight."""
    return (e[0], e[4], -e[5], e[6], e[1], -e[2], e[3], e[7])


def serial_entries_along_axis(entries: np.ndarray, element_x: np.ndarray, output_x: np.ndarray) -> np.ndarray:
    """Eq. 1 on the eight entries: (8, ...) at the output of elements along its x axis.

    entries (n, 8, ...) of each element at its loaded end in the output's axes (``hinge.ENTRY_INDEX``
    order); element_x (n, ...) [m] the x of each loaded end; output_x (...) [m] the output's x.
    """
    e = np.moveaxis(np.asarray(entries, dtype=float), 1, 0)  # (8, n, ...)
    d = np.asarray(element_x, dtype=float) - np.asarray(output_x, dtype=float)
    return np.stack(moved_along_axis(e, d)).sum(axis=1)
