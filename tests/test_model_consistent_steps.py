"""The consistent model's work per posture (``model._numba_consistent``): evaluations of the
fixed-point map Phi, counted by the kernel (deterministic, not a timing). Its speed is this count
times ~1-1.5 us CPU per evaluation (benchmarks/bench_model.py, docs/model.md 10)."""

import dataclasses

import numpy as np
import pytest

from flexcal.model import kernel
from flexcal.model.assembly import mechanism_matrices
from flexcal.model.consistent import solve_points_consistent
from flexcal.model.forward import CONSISTENT_MAX_ITER, CONSISTENT_TOL, DIVERGENCE_LIMIT, STATE_TOLERANCE
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import standard_trajectory

pytestmark = pytest.mark.skipif(not kernel.available(), reason="the consistent model runs in the compiled engine")


def test_the_fixed_point_needs_few_evaluations_per_posture():
    """40 uniform random candidates (those of the convergence test) on the standard trajectory,
    with the play state: Broyden steps from a start moved by the linear response, the previous
    points' drift and the measured dX/dC take 13.4 evaluations per posture on average (5.1 where
    every nut sits on its flank, 22.3 where one is off it: the probes); the plain fixed point
    from the previous pose took 25.9 (10.3 / 42.6)."""
    space = dataclasses.replace(parameter_space(), second_order=True, chain_shortening=tuple(np.zeros(216)),
                                breakaway_force=2.0)
    values = space.from_unit(np.random.default_rng(0).random((40, 45)))
    out = solve_points_consistent(mechanism_matrices(values, space), standard_trajectory().inputs, clearance=True,
                                  tol=CONSISTENT_TOL, max_iter=CONSISTENT_MAX_ITER, divergence=DIVERGENCE_LIMIT,
                                  state_tolerance=STATE_TOLERANCE)
    assert np.all(out["codes"] == 0)
    engaged = out["point_class"] == 1
    assert 0.2 < np.mean(engaged) < 0.8  # both kinds of posture are visited
    # bounds halfway between after and before: the counts move by a few per cent with the
    # rounding of the starts, a regression to the plain fixed point moves them by ~2x
    assert np.mean(out["iterations"]) <= 20.0, np.mean(out["iterations"])
    assert np.mean(out["iterations"][engaged]) <= 8.0, np.mean(out["iterations"][engaged])  # after 5.1, before ~10
