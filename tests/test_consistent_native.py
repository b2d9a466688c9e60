"""The consistent model's map and equilibrium in C with the six chains as vector lanes
(``model/_consistent_map.c``, ``model/consistent_native.py``; docs/model.md 10, "Session 42"): the
same formulas as numba's ``_terms`` and ``_equilibrium``, so the same numbers to rounding, and
the kernel without the extension (numba's copies) gives the same results."""

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from numba import njit

from flexcal.model import consistent_native, kernel
from flexcal.model import _numba_consistent as nc
from flexcal.model.assembly import mechanism_matrices
from flexcal.model.consistent import defect_terms, lane_rows, pack_chains, solve_points_consistent
from flexcal.model.forward import CONSISTENT_MAX_ITER, CONSISTENT_TOL, DIVERGENCE_LIMIT, STATE_TOLERANCE
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import standard_trajectory

pytestmark = [pytest.mark.skipif(not kernel.available(), reason="the consistent model runs in the compiled engine"),
              pytest.mark.skipif(not consistent_native.AVAILABLE, reason="flexcal.model._consistent_map not built")]


def _space(**changes):
    return dataclasses.replace(parameter_space(), second_order=True, chain_shortening=tuple(np.zeros(216)), **changes)


@njit
def _both_maps(lanes, pack, cand, x, c, command, x0, axial, point_b, index, defect, symmetric, weight):
    """(r, u, n, force) of the C map and of numba's ``_terms`` at one pose, as rows."""
    out = np.zeros((2, 4, 8))
    consistent_native.terms(cand, lanes.shape[1], lanes.ctypes, x.ctypes, c.ctypes, command.ctypes, x0.ctypes,
                            weight.ctypes, index.shape[0], index.ctypes, 1 if symmetric else 0, out[0, 0].ctypes,
                            out[0, 1].ctypes, out[0, 2].ctypes, out[0, 3].ctypes)
    scratch = np.zeros((3, 8))
    nc._terms(cand, x, c, command, x0, axial, pack, point_b, index, defect, symmetric, weight, out[1, 0, :6],
              out[1, 1, :6], out[1, 2, :6], out[1, 3], scratch[0], scratch[1], scratch[2])
    return out


@pytest.mark.parametrize("symmetric", [True, False])
def test_the_lane_map_equals_numbas_terms(symmetric):
    """At 20 random poses of 5 random candidates (strokes up to 2x the standard ones, offsets inside
    the clearance): every output of the map, the written-out defect (``symmetric``) and the loop over
    its index alike. The sums are the same in another order, so they agree to rounding: 1e-12 of each
    output's largest entry (measured <= 2e-15 for the shortening, loads and wrench; the loads'
    relative rounding is that of tension ~ 1e3 N from terms ~ 1e8 N/m x 1e-5 m)."""
    space = _space()
    rng = np.random.default_rng(4)
    m = mechanism_matrices(space.from_unit(rng.random((5, 45))), space)
    index, defect = defect_terms(m.lateral_defect)
    no_frame = np.zeros((5, 6, 6))  # the frame rows are the equilibrium's, not the map's
    lanes, pack = lane_rows(m, defect, no_frame, no_frame[:, 0]), pack_chains(m)
    pose = standard_trajectory().inputs
    worst = np.zeros(4)
    for trial in range(20):
        cand = trial % 5
        x = np.concatenate([rng.normal(0.0, 2e-5, 3), rng.normal(0.0, 2e-3, 3)])
        c = rng.uniform(0.0, 1e-4, 3)
        command = 2.0 * pose[rng.integers(len(pose))].astype(float)
        out = _both_maps(lanes, pack, cand, x, c, command, np.ascontiguousarray(m.initial_position),
                         np.ascontiguousarray(m.axial_stiffness), np.ascontiguousarray(m.point_b), index, defect,
                         symmetric, np.ascontiguousarray(m.payload))
        c_map, numba_map = out[0], out[1]
        assert np.all(np.isfinite(c_map)) and np.all(c_map[:, 6:] == 0.0)  # lanes 6, 7 and force's 6, 7 stay zero
        for k in range(4):
            worst[k] = max(worst[k], np.abs(c_map[k] - numba_map[k]).max() / np.abs(numba_map[k]).max())
    assert np.all(worst <= 1e-12), worst  # rounding of the same sums in another order (docstring)


def _runs(m, inputs, **options):
    return [solve_points_consistent(m, inputs, clearance=True, tol=CONSISTENT_TOL, max_iter=CONSISTENT_MAX_ITER,
                                    divergence=DIVERGENCE_LIMIT, state_tolerance=STATE_TOLERANCE, native=flag,
                                    **options) for flag in (True, False)]


def test_the_c_equilibrium_gives_numbas_results():
    """40 uniform random candidates with the play state (those of test_consistent_written_out): the
    same poses and offsets as numba's kernel, to the iteration's own tolerance, every point
    converged, about the same evaluations; and on 1 or 2 threads the same bits."""
    space = _space(breakaway_force=2.0)
    m = mechanism_matrices(space.from_unit(np.random.default_rng(0).random((40, 45))), space)
    inputs = standard_trajectory().inputs
    native, numba_run = _runs(m, inputs)
    assert np.all(native["codes"] == 0) and np.all(numba_run["codes"] == 0)
    # 5e-13 rad / 2e-13 m, the bounds of test_the_written_out_terms_keep_the_results_with_the_clearance
    # (the same cause: other rounding ends the iterations elsewhere inside their tolerance)
    np.testing.assert_allclose(native["pose"], numba_run["pose"], rtol=0, atol=5e-13)
    # 2e-13 m: the Newton steps' own stop on the offsets (1e-13 m) x 2
    np.testing.assert_allclose(native["clearance"], numba_run["clearance"], rtol=0, atol=2e-13)
    np.testing.assert_array_equal(native["states"], numba_run["states"])
    # the same iteration: the evaluations differ where rounding moves a stop by one step (2 % of the total)
    assert abs(native["iterations"].sum() / numba_run["iterations"].sum() - 1.0) <= 0.02
    two = solve_points_consistent(m, inputs, clearance=True, tol=CONSISTENT_TOL, max_iter=CONSISTENT_MAX_ITER,
                                  divergence=DIVERGENCE_LIMIT, state_tolerance=STATE_TOLERANCE, n_threads=2)
    assert all(np.array_equal(two[key], native[key]) for key in native)


def test_a_non_converging_equilibrium_reports_its_status():
    """max_iter 1: the C equilibrium's status travels back as numba's (not converged), as does the
    evaluation count."""
    space = _space(breakaway_force=2.0)
    m = mechanism_matrices(space.from_unit(np.random.default_rng(1).random((3, 45))), space)
    runs = [solve_points_consistent(m, standard_trajectory().inputs, clearance=True, tol=CONSISTENT_TOL,
                                    max_iter=1, divergence=DIVERGENCE_LIMIT, state_tolerance=STATE_TOLERANCE,
                                    native=flag) for flag in (True, False)]
    from flexcal.model.point_status import NOT_CONVERGED

    assert np.any(runs[0]["codes"] == NOT_CONVERGED)
    np.testing.assert_array_equal(runs[0]["codes"] != 0, runs[1]["codes"] != 0)


_WITHOUT_EXTENSION = """
import sys
sys.modules["flexcal.model._consistent_map"] = None  # as on a machine without a C compiler
import dataclasses
import numpy as np
from flexcal.model import consistent_native
from flexcal.model.forward import forward
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import standard_trajectory
assert not consistent_native.AVAILABLE
space = dataclasses.replace(parameter_space(), second_order=True, chain_shortening=tuple(np.zeros(216)),
                            breakaway_force=2.0)
values = space.from_unit(np.random.default_rng(5).random((3, 45)))
result = forward(values, standard_trajectory().inputs, space=space, n_threads=1)
np.save(sys.argv[1], result.pose)
"""


def test_the_kernel_runs_numbas_copy_without_the_extension(tmp_path):
    """In a process where the extension cannot be imported the placeholder symbols let the kernel
    link, numba's copies run, and the default model gives this process's poses to rounding."""
    from flexcal.model.forward import forward

    space = _space(breakaway_force=2.0)
    values = space.from_unit(np.random.default_rng(5).random((3, 45)))
    here = forward(values, standard_trajectory().inputs, space=space, n_threads=1).pose
    subprocess.run([sys.executable, "-c", _WITHOUT_EXTENSION, str(tmp_path / "pose.npy")], check=True)
    # 5e-13 rad: the bound of test_the_c_equilibrium_gives_numbas_results (the same two iterations)
    np.testing.assert_allclose(np.load(tmp_path / "pose.npy"), here, rtol=0, atol=5e-13)


def test_the_set_up_split_over_threads_gives_the_same_bits():
    """The consistent set-up's chain kernels and the lane rows split their rows over threads
    (model/threads.py): every field of the matrices and every lane row to the bit, 1 or 2 threads
    (each row is computed on its own)."""
    space = _space(breakaway_force=2.0)
    values = space.from_unit(np.random.default_rng(7).random((9, 45)))
    one, two = (mechanism_matrices(values, space, n_threads=n) for n in (1, 2))
    for field in dataclasses.fields(one):
        a, b = getattr(one, field.name), getattr(two, field.name)
        if isinstance(a, np.ndarray):
            assert np.array_equal(a, b), field.name
    _, defect = defect_terms(one.lateral_defect)
    frame = np.random.default_rng(8).random((9, 6, 6))
    assert np.array_equal(lane_rows(one, defect, frame, frame[:, 0], 1), lane_rows(one, defect, frame, frame[:, 0], 2))
    assert np.array_equal(pack_chains(one, 1), pack_chains(one, 2))


def test_the_c_map_runs_only_where_the_zeros_it_skips_are_there():
    """The C map skips the zero entries of the chain stiffness (off its blocks), of the transform's
    rotation rows (the frame's translation) and of the load form (off its lateral rows and columns):
    they hold for random candidates; a matrix with such an entry falls back to numba's copy, or
    raises where the C copy is asked for, instead of giving a wrong pose."""
    from flexcal.model.consistent import lanes_apply

    space = _space(breakaway_force=2.0)
    m = mechanism_matrices(space.from_unit(np.random.default_rng(2).random((4, 45))), space)
    assert lanes_apply(m)
    inputs = standard_trajectory().inputs[:12]
    options = dict(clearance=True, tol=CONSISTENT_TOL, max_iter=CONSISTENT_MAX_ITER, divergence=DIVERGENCE_LIMIT,
                   state_tolerance=STATE_TOLERANCE)
    for field, index in (("chain_stiffness", (1, 2, 1, 3)), ("frame_transform", (0, 4, 3, 1)),
                         ("load_shortening", (3, 0, 3, 2))):
        values = getattr(m, field).copy()
        values[index] = 1e-3 * np.abs(values).max()
        other = dataclasses.replace(m, **{field: values})
        assert not lanes_apply(other)
        automatic = solve_points_consistent(other, inputs, **options)
        reference = solve_points_consistent(other, inputs, native=False, **options)
        assert all(np.array_equal(automatic[key], reference[key]) for key in reference)
        with pytest.raises(ValueError, match="lanes_apply"):
            solve_points_consistent(other, inputs, native=True, **options)
