"""The consistent kernel's lateral defect terms written out (session 21, docs/model.md 10): for
chains symmetric about their axis ``consistent.defect_terms`` lays the terms out as
``_numba_consistent.SYMMETRIC_DEFECT`` and ``_terms`` sums them as products of locals instead of
the loop over their index (~1/4 of the kernel's time). Same sums, other rounding."""

import dataclasses

import numpy as np
import pytest

from flexcal.model import kernel
from flexcal.model.assembly import mechanism_matrices
from flexcal.model.consistent import defect_terms, solve_points_consistent
from flexcal.model.forward import CONSISTENT_MAX_ITER, CONSISTENT_TOL, DIVERGENCE_LIMIT, STATE_TOLERANCE
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import standard_trajectory

pytestmark = pytest.mark.skipif(not kernel.available(), reason="the consistent model runs in the compiled engine")


def _space(**changes):
    return dataclasses.replace(parameter_space(), second_order=True, chain_shortening=tuple(np.zeros(216)), **changes)


def test_symmetric_chains_get_the_written_out_layout_and_others_the_loop():
    from flexcal.model._numba_consistent import SYMMETRIC_DEFECT

    space = _space()
    lateral = mechanism_matrices(space.from_unit(np.random.default_rng(0).random((5, 45))), space).lateral_defect
    index, q = defect_terms(lateral)
    assert np.array_equal(index, SYMMETRIC_DEFECT)
    # the coefficients in that order: q = L[c-1, a, b] (x2 off the diagonal), none lost
    expected = lateral[:, :, index[:, 0] - 1, index[:, 1], index[:, 2]] * np.where(index[:, 1] == index[:, 2], 1, 2)
    np.testing.assert_array_equal(q, expected)
    # a chain with a term outside the symmetric set: the general index (the union, in (c, a, b) order)
    other = lateral.copy()
    other[0, 0, 0, 1, 1] = 0.5  # (c, a, b) = (1, 1, 1): not in SYMMETRIC_DEFECT
    index_other, q_other = defect_terms(other)
    assert len(index_other) == len(SYMMETRIC_DEFECT) + 1 and [1, 1, 1] in index_other.tolist()
    assert q_other[0, 0, index_other.tolist().index([1, 1, 1])] == 0.5


def test_the_written_out_terms_give_the_loops_fixed_points():
    """Without clearance the pose is the map's fixed point alone: written out or looped, the defect's
    sums differ by rounding only, and so do the poses, at 2.5x the standard trajectory's strokes
    (the designs' size, where the defect's forces are ~1 % of the chains' lateral forces: a missing
    or misplaced term moves the poses by far more)."""
    space = _space()
    m = mechanism_matrices(space.from_unit(np.random.default_rng(3).random((6, 45))), space)
    inputs = 2.5 * standard_trajectory().inputs[::5]
    runs = [solve_points_consistent(m, inputs, clearance=False, tol=1e-15, max_iter=200, divergence=1e-2,
                                    state_tolerance=1e-12, written_out=flag) for flag in (True, False)]
    # 1e-14 rad, as test_the_compiled_solve_equals_a_plain_loop: the two sums round differently,
    # their fixed points agree to the last bits (without any one term but the rounding-level
    # (3, 1, 2) the poses here move by 3.7e-10 to 1.3e-7 rad, measured)
    np.testing.assert_allclose(runs[0]["pose"], runs[1]["pose"], rtol=0, atol=1e-14)


def test_the_written_out_terms_keep_the_results_with_the_clearance():
    """40 uniform random candidates with the play state (those of tests/test_model_consistent_steps.py):
    the same poses and offsets as the loop, to the iteration's own tolerance."""
    space = _space(breakaway_force=2.0)
    m = mechanism_matrices(space.from_unit(np.random.default_rng(0).random((40, 45))), space)
    runs = [solve_points_consistent(m, standard_trajectory().inputs, clearance=True, tol=CONSISTENT_TOL,
                                    max_iter=CONSISTENT_MAX_ITER, divergence=DIVERGENCE_LIMIT,
                                    state_tolerance=STATE_TOLERANCE, written_out=flag) for flag in (True, False)]
    assert all(np.all(run["codes"] == 0) for run in runs)
    # 5e-13 rad / 2e-13 m, the bounds of test_the_default_tolerances_agree_with_tighter_ones: other
    # rounding may end the probes' iterations elsewhere inside their tolerance (measured 1.1e-15 rad /
    # 7e-16 m here, 3.1e-15 rad / 1.4e-15 m on 300 candidates)
    np.testing.assert_allclose(runs[0]["pose"], runs[1]["pose"], rtol=0, atol=5e-13)
    # 2e-13 m: the Newton steps' own stop on the offsets (1e-13 m) x 2
    np.testing.assert_allclose(runs[0]["clearance"], runs[1]["clearance"], rtol=0, atol=2e-13)
