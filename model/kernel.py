"""The compiled engine behind ``forward`` (numba): the per-point solve of Eq. 8, and
compiled copies of the hinge/chain formulas for large batches.

The per-point solve is the algorithm of ``solver.solve_points`` (the numpy reference,
which documents it), written point by point so that nothing is allocated per point:
candidates in parallel (numba threads), points in trajectory order, each point starting
from the previous point's parasitic term, clearance and chain statuses. Iterate
``v = r + C`` with

    Delta = Delta_in + Q v,  r_i = -K_Li (Delta_y,i^2 + Delta_z,i^2),
    a = mu/s N_D(C = 0, r),  C = clip(a + B C, lo, hi)  (solved exactly every step)

until max |dv| <= tol at that point. The clearance box QP is solved by active-set sweeps
from the warm start, falling back to enumerating its 27 faces. Status codes per point:
0 converged, 1 no convergence in max_iter, 2 diverged, 3 clearance solve failed
(``point_status``); pose, loads, release, states and class are computed in the same pass.

numba is imported only when a compiled function runs (``import flexcal.model`` stays
fast); ``available()`` says whether it can be. It comes with CadQuery here.
"""

from __future__ import annotations

import contextlib
import functools

import numpy as np

__all__ = ["available", "solve_points_compiled", "arc_quadrature_compiled", "chain_entries_compiled",
           "chain_entries_elements_compiled", "assemble_compiled"]

_FACES = np.array([[i, j, k] for i in range(3) for j in range(3) for k in range(3)], dtype=np.int64)


@functools.lru_cache(maxsize=None)
def available() -> bool:
    """True if numba imports (the compiled engine can be used)."""
    try:
        import numba  # noqa: F401
    except Exception:  # pragma: no cover - depends on the environment
        return False
    return True


@contextlib.contextmanager
def numba_threads(n_threads: int):
    """numba's parallel regions on ``n_threads`` threads (clamped to 1..NUMBA_NUM_THREADS)
    inside the block, this thread's previous count given back after it."""
    import numba

    previous = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(n_threads), numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(previous)


def _kernels():
    from . import _numba_kernels

    return _numba_kernels.solve, _numba_kernels.arc_quadrature, _numba_kernels.chain_entries


def assemble_compiled(stiffness, rotation, point_b, centre, wrench) -> dict[str, np.ndarray]:
    """Compiled linear algebra of ``assembly.mechanism_matrices`` (same formulas).

    stiffness K_i (n_c, 6, 6, 6), rotation (n_c, 6, 3, 3), point_b (6, 3) [m], centre
    (n_c, 6, 3) [m] B-side flexure centres, wrench F_C (6,). Returns "frame_transform",
    "frame_stiffness", "axial_gain", "input_gain", "gravity_pose", "parasitic_rows",
    "parasitic_gain", "parasitic_gravity" (shapes as in ``MechanismMatrices``).
    """
    from . import _numba_kernels

    n_c = stiffness.shape[0]
    out = {"frame_transform": np.empty((n_c, 6, 6, 6)), "frame_stiffness": np.empty((n_c, 6, 6)),
           "axial_gain": np.empty((n_c, 6, 6)), "input_gain": np.empty((n_c, 6, 6)), "gravity_pose": np.empty((n_c, 6)),
           "parasitic_rows": np.empty((n_c, 12, 6)), "parasitic_gain": np.empty((n_c, 12, 6)),
           "parasitic_gravity": np.empty((n_c, 12))}
    c = np.ascontiguousarray
    _numba_kernels.assemble(c(stiffness, dtype=float), c(rotation, dtype=float), c(point_b, dtype=float),
                            c(centre, dtype=float), c(wrench, dtype=float), *out.values())
    return out


def _flat_batch(*values) -> tuple[tuple[int, ...], list[np.ndarray]]:
    """The values broadcast to one batch shape, and each as its own flat float copy (numba warns
    on a broadcast view)."""
    arrays = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in values))
    return arrays[0].shape, [np.array(v, dtype=float).reshape(-1) for v in arrays]


def chain_entries_compiled(length, hinge_length, width, fillet, thickness_1, thickness_2, section, connector,
                           end_block, actuator_compliance, material, shear_coefficient, nodes, weights) -> np.ndarray:
    """Compiled ``chain.chain_compliance_entries``: broadcast inputs -> (..., 8) entries.

    shear_coefficient [-]: Timoshenko's coefficient of ``material`` (``hinge.shear_coefficient``).
    """
    shape, flat = _flat_batch(length, hinge_length, width, fillet, thickness_1, thickness_2, section, connector,
                              end_block, actuator_compliance)
    out = np.empty((flat[0].size, 8))
    _kernels()[2](*flat, float(material.youngs_modulus), float(material.shear_modulus),
                  float(shear_coefficient), np.asarray(nodes, float),
                  np.asarray(weights, float), out)
    return out.reshape(shape + (8,))


def chain_entries_elements_compiled(length, hinge_length, width, fillet, thickness_1, thickness_2, section, connector,
                                    end_block, material, shear_coefficient, nodes, weights, n_threads: int = 1
                                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compiled ``chain.chain_entries_and_elements``: broadcast inputs -> entries (..., 8), element
    entries (..., 9, 8) and offsets (..., 9) [m]; the chains split over ``n_threads`` (``threads``)."""
    from . import _numba_kernels
    from .threads import run_split

    shape, flat = _flat_batch(length, hinge_length, width, fillet, thickness_1, thickness_2, section, connector,
                              end_block)
    n = flat[0].size
    out, elements, offsets = np.empty((n, 8)), np.empty((n, 9, 8)), np.empty((n, 9))
    constants = (float(material.youngs_modulus), float(material.shear_modulus), float(shear_coefficient),
                 np.asarray(nodes, float), np.asarray(weights, float))
    run_split(lambda first, stop: _numba_kernels.chain_entries_elements(
        *(part[first:stop] for part in flat), *constants, out[first:stop], elements[first:stop],
        offsets[first:stop]), n, n_threads)
    return out.reshape(shape + (8,)), elements.reshape(shape + (9, 8)), offsets.reshape(shape + (9,))


def arc_quadrature_compiled(radius, thickness, width, nodes, weights) -> np.ndarray:
    """Compiled ``hinge._arc_quadrature``: broadcast inputs -> (..., 3) [u^2/t, u^2/t^3, 1/J integrals]."""
    r, t, w = np.broadcast_arrays(np.asarray(radius, float), np.asarray(thickness, float), np.asarray(width, float))
    out = np.empty((r.size, 3))
    _kernels()[1](np.ascontiguousarray(r).ravel(), np.ascontiguousarray(t).ravel(), np.ascontiguousarray(w).ravel(),
                  np.asarray(nodes, float), np.asarray(weights, float), out)
    return out.reshape(r.shape + (3,))


def solve_points_compiled(matrices, inputs: np.ndarray, directions: np.ndarray, *, parasitic: bool, clearance: bool,
                          tol: float, max_iter: int, divergence: float, state_tolerance: float,
                          n_threads: int = 1) -> dict[str, np.ndarray]:
    """Run the compiled kernel on ``n_threads`` numba threads (candidates in parallel).
    ``directions`` (n_p, 3) are the ones the clearance uses.

    Returns (n_c, n_p, k) arrays "pose", "loads", "clearance", "release", "parasitic",
    "states" (int8), "point_class" (int8), "codes", "iterations" (see ``forward``).
    """
    from .clearance import clearance_coupling
    from .parameters import DRIVING

    m = matrices
    n_c, n_p = m.n_candidates, inputs.shape[0]
    solve = _kernels()[0]
    out = {"pose": np.empty((n_c, n_p, 6)), "loads": np.empty((n_c, n_p, 6)), "clearance": np.empty((n_c, n_p, 3)),
           "release": np.empty((n_c, n_p, 3)), "parasitic": np.empty((n_c, n_p, 6)),
           "states": np.empty((n_c, n_p, 3), dtype=np.int8), "point_class": np.empty((n_c, n_p), dtype=np.int8),
           "codes": np.empty((n_c, n_p), dtype=np.int64), "iterations": np.empty((n_c, n_p), dtype=np.int64)}
    c = np.ascontiguousarray
    arguments = (
        c(m.parasitic_gain), c(m.parasitic_gravity), c(-m.parasitic_coefficient), c(m.load_gain[:, DRIVING]),
        c(m.gravity_loads[:, DRIVING]), c(m.mu / m.nut_stiffness),
        c(clearance_coupling(m.coupling[:, DRIVING, DRIVING], m.nut_stiffness, m.mu)), c(m.clearance),
        c(m.initial_position), c(inputs, dtype=float), c(directions, dtype=float), bool(parasitic), bool(clearance),
        float(tol), int(max_iter), float(divergence), _FACES, c(m.input_gain), c(m.gravity_pose), c(m.load_gain),
        c(m.gravity_loads), c(m.nut_stiffness), float(state_tolerance), c(np.maximum(m.breakaway_band, 0.0)),
        bool(clearance and np.all(m.breakaway_band >= 0)), out["pose"], out["loads"], out["clearance"],
        out["release"], out["parasitic"], out["states"], out["point_class"], out["codes"], out["iterations"])
    with numba_threads(n_threads):
        solve(*arguments)
    return out
