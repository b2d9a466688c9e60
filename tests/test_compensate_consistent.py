"""``flexcal compensate`` with the consistent model and the clearance's play state (issue 24,
session 16): the model is driven along the bench's ordered sequence (0, x_1, 0, x_2, ...,
``validation.runs.compensate.sequence_angles``) on the compiled engine, its inverse and input
Jacobian by central differences of that ordered run."""

import json

import numpy as np
import pytest

from flexcal.validation import cli
from flexcal.validation.runs.compensate import drives_in_order, sequence_angles, sequence_jacobian
from flexcal.validation.runs.model_correction import model_space


def test_the_ordered_model_is_path_dependent_and_its_jacobian_is_the_difference():
    space = model_space("closed-form", model="consistent")
    assert drives_in_order(space) and not drives_in_order(model_space("closed-form"))
    values = space.nominal_full
    x = np.array([[0.4e-3, -0.3e-3, 0.2e-3], [-0.2e-3, 0.5e-3, -0.4e-3]])
    forward_then_back = sequence_angles(values, x, space)
    assert forward_then_back.shape == (2, 3) and np.all(np.isfinite(forward_then_back))
    # the second target's angles depend on the first target (the nuts' offsets carried over)
    other_first = sequence_angles(values, np.array([[-0.4e-3, 0.3e-3, -0.2e-3], x[1]]), space)
    assert np.max(np.abs(other_first[1] - forward_then_back[1])) > 0.0
    jacobian = sequence_jacobian(values, x, space)
    step = np.array([2e-6, -1e-6, 1.5e-6])
    predicted = forward_then_back + np.einsum("nij,j->ni", jacobian, step)
    moved = sequence_angles(values, x + step, space)
    # a 2 um move: the Jacobian predicts the change to its second order (~1e-3 of it) and the
    # cross-target term it leaves out; 2 % of the change is 20x that
    change = moved - forward_then_back
    bound = 0.02 * np.max(np.abs(change))  # 20x the second-order and cross-target terms (above)
    np.testing.assert_allclose(change, predicted - forward_then_back, rtol=0, atol=bound)  # bound: line above


@pytest.mark.slow
def test_compensate_with_the_consistent_model_runs_beats_the_uncompensated_error_and_repeats(tmp_path):
    """The analytic prototype's noisy curve, ``flexcal compensate --model consistent`` (closed-form
    chains: no FEM) twice with the same seed: both runs finish, their reports agree to the byte,
    and the first round's mean error is below the uncompensated (small-deflection) inputs' one on
    every angle. Slow: two identifications of the consistent model."""
    assert cli.main(["truth", "--scenario", "table1", "--provider", "analytic", "--noise-urad", "0.5",
                     "--out", str(tmp_path / "t"), "-q"]) == 0
    argv = ["compensate", "--data", str(tmp_path / "t" / "curves.csv"), "--model", "consistent",
            "--model-stiffness", "closed-form", "--particles", "60", "--iterations", "10", "--sobol-n", "32",
            "--max-rounds", "2"]
    reports = []
    for k in range(2):
        assert cli.main([*argv, "--out", str(tmp_path / f"c{k}"), "-q"]) == 0
        reports.append((tmp_path / f"c{k}" / "report.json").read_bytes())
    assert reports[0] == reports[1]
    report = json.loads(reports[0])
    reduction = report["first_round_mean_reduction_pct"]
    assert all(reduction[angle] > 0.0 for angle in reduction), reduction
