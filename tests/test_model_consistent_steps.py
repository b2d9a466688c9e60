"""The consistent model's work per posture (``model._numba_consistent``): evaluations of the
fixed-point map Phi, counted by the kernel (deterministic, not a timing). Its speed is this count
times ~1-1.5 us CPU per evaluation (benchmarks/bench_model.py, docs/model.md 10)."""

import dataclasses

import numpy as np
import pytest

from flexcal.model import kernel
from flexcal.model.assembly import mechanism_matrices
from flexcal.model import consistent
from flexcal.model.consistent import solve_points_consistent
from flexcal.model.forward import CONSISTENT_MAX_ITER, CONSISTENT_TOL, DIVERGENCE_LIMIT, STATE_TOLERANCE
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import standard_trajectory

pytestmark = pytest.mark.skipif(not kernel.available(), reason="the consistent model runs in the compiled engine")


def _forty_candidates():
    """The matrices of 40 uniform random candidates (seed 0) of the consistent space with the play state."""
    space = dataclasses.replace(parameter_space(), second_order=True, chain_shortening=tuple(np.zeros(216)),
                                breakaway_force=2.0)
    return mechanism_matrices(space.from_unit(np.random.default_rng(0).random((40, 45))), space)


def _solve(matrices, inputs, tol=CONSISTENT_TOL, **options):
    """``solve_points_consistent`` with the forward model's settings and the clearance on."""
    return solve_points_consistent(matrices, inputs, clearance=True, tol=tol, max_iter=CONSISTENT_MAX_ITER,
                                   divergence=DIVERGENCE_LIMIT, state_tolerance=STATE_TOLERANCE, **options)


def test_the_fixed_point_needs_few_evaluations_per_posture():
    """40 uniform random candidates (those of the convergence test) on the standard trajectory,
    with the play state: Broyden steps from a start moved by the linear response, the previous
    points' drift and the measured dX/dC take 13.4 evaluations per posture on average (5.1 where
    every nut sits on its flank, 22.3 where one is off it: the probes); the plain fixed point
    from the previous pose took 25.9 (10.3 / 42.6)."""
    out = _solve(_forty_candidates(), standard_trajectory().inputs)
    assert np.all(out["codes"] == 0)
    engaged = out["point_class"] == 1
    assert 0.2 < np.mean(engaged) < 0.8  # both kinds of posture are visited
    # bounds halfway between after and before: the counts move by a few per cent with the
    # rounding of the starts, a regression to the plain fixed point moves them by ~2x
    assert np.mean(out["iterations"]) <= 20.0, np.mean(out["iterations"])
    assert np.mean(out["iterations"][engaged]) <= 8.0, np.mean(out["iterations"][engaged])  # after 5.1, before ~10


def test_the_default_tolerances_agree_with_tighter_ones():
    """The same 40 candidates with the play state, solved at the default tolerance (offsets 1e-13 m,
    the pose 1e-15) and at 30x tighter ones: the poses agree to 1.1e-13 rad and the offsets to
    3.5e-14 m (session 15, both before and after the kernel stopped re-evaluating the map after a
    converged equilibrium where no probe follows). Without the re-evaluation before the probes
    too, the rates' error moved the poses by 1.3e-12 rad here (2.7e-12 on 300 candidates)."""
    matrices = _forty_candidates()
    runs = [_solve(matrices, standard_trajectory().inputs, tol) for tol in (CONSISTENT_TOL, CONSISTENT_TOL / 30)]
    assert all(np.all(run["codes"] == 0) for run in runs)
    # 5e-13 rad / 2e-13 m: ~4x the measured 1.1e-13 / 3.5e-14 (rounding of the probes' rates),
    # below the 1.3e-12 rad an under-resolved rate gives (checked: that variant fails here)
    np.testing.assert_allclose(runs[0]["pose"], runs[1]["pose"], rtol=0, atol=5e-13)
    # 2e-13 m: ~6x the measured 3.5e-14 m of the offsets, the Newton steps' own stop (1e-13 m) x 2
    np.testing.assert_allclose(runs[0]["clearance"], runs[1]["clearance"], rtol=0, atol=2e-13)


def test_a_revisited_command_starts_from_its_earlier_equilibrium():
    """The standard trajectory goes out and back along each leg: a point whose command was solved
    before, with the nut offsets it had then, starts from that equilibrium (``consistent.revisits``;
    session 16). Where every nut stays on its flank that start is the fixed point itself: one
    evaluation of the map confirms it (4.2 on average from the drift-extrapolated start). The
    results are those of the solve without it, to the iteration's own tolerance."""
    commands = np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 0], [0, 0, 1]])
    first = consistent.revisits(commands)
    assert first.tolist() == [-1, -1, 0, 1, -1]
    first[:] = 7  # remembered per trajectory: a caller's copy, not the memory
    assert consistent.revisits(commands).tolist() == [-1, -1, 0, 1, -1]
    assert consistent.revisits(commands[:, ::-1]).tolist() == [-1, -1, 0, 1, -1]  # a strided view, read as values
    assert consistent.revisits(commands[[0, 2, 1]]).tolist() == [-1, 0, -1]  # another trajectory
    matrices, inputs = _forty_candidates(), standard_trajectory().inputs
    runs = [_solve(matrices, inputs, revisit=revisit) for revisit in (True, False)]
    assert all(np.all(run["codes"] == 0) for run in runs)
    # 5e-13 rad, the bound of test_the_default_tolerances_agree_with_tighter_ones: another start
    # ends the iteration elsewhere inside its tolerance (measured 8.7e-14 rad here)
    np.testing.assert_allclose(runs[0]["pose"], runs[1]["pose"], rtol=0, atol=5e-13)
    # 2e-13 m: the Newton steps' own stop on the offsets (1e-13 m) x 2, as in that test
    np.testing.assert_allclose(runs[0]["clearance"], runs[1]["clearance"], rtol=0, atol=2e-13)
    earlier = consistent.revisits(inputs)
    engaged = np.all(runs[0]["states"] == 0, axis=2)  # (n_c, n_p): every nut on its flank
    points = np.nonzero(earlier >= 0)[0]
    points = points[points > 0]
    same = engaged[:, points] & engaged[:, points - 1] & engaged[:, earlier[points]]  # same offsets (0) then and now
    assert same.sum() > 200  # enough such points to count (317 of the 40 x 77 here)
    assert np.all(runs[0]["iterations"][:, points][same] == 1)
    assert np.mean(runs[1]["iterations"][:, points][same]) > 3.0  # without: 4.2 from the drift-extrapolated start


def test_reusing_the_previous_points_rates_at_a_loose_step_keeps_the_results():
    """Session 19: a point's loose first Newton step on the offsets takes the previous point's last
    tight rates of a nut off its flank there too instead of probing it (``reuse_rates``). The 40
    random candidates with the play state: the same poses and offsets as probing every step (the
    code before), and as a 30x tighter solve, to the iteration's own tolerance, with fewer
    evaluations of the map (measured 11.6 -> 10.8 per posture here, 12.2 -> 11.3 on 300)."""
    matrices, inputs = _forty_candidates(), standard_trajectory().inputs
    runs = [_solve(matrices, inputs, tol, reuse_rates=reuse)
            for tol, reuse in ((CONSISTENT_TOL, True), (CONSISTENT_TOL, False), (CONSISTENT_TOL / 30, False))]
    assert all(np.all(run["codes"] == 0) for run in runs)
    for other in runs[1:]:
        # 5e-13 rad / 2e-13 m, the bounds of test_the_default_tolerances_agree_with_tighter_ones:
        # the loose step's rates only change where the tight steps start (measured 2.2e-13 rad /
        # 7e-14 m here; 2.7e-13 rad / 8e-14 m between the two paths and 1.6-1.9e-13 rad from the
        # tighter solve on 300 candidates, where the probing path is 1.5-1.6e-13 rad from it)
        np.testing.assert_allclose(runs[0]["pose"], other["pose"], rtol=0, atol=5e-13)
        # 2e-13 m: the Newton steps' own stop on the offsets (1e-13 m) x 2
        np.testing.assert_allclose(runs[0]["clearance"], other["clearance"], rtol=0, atol=2e-13)
    # 0.95: measured 0.927 here, 0.925 on 300 random candidates (seeds 0 and 1); a reuse that never
    # happens gives 1.0
    assert np.mean(runs[0]["iterations"]) <= 0.95 * np.mean(runs[1]["iterations"])
