"""Where the MAP fits start (``IdentificationSettings.start``, ``flexcal verify --start``): an
earlier estimate instead of the prior mean, for designed trajectories whose large strokes can
trap a fit from the prior mean (docs/calibration.md 11, session 18)."""

import numpy as np
import pytest

import flexcal.calibration.estimation as estimation
import flexcal.calibration.pipeline as pipeline
from flexcal.calibration.offset_chart import offset_chart
from flexcal.calibration.pipeline import IdentificationSettings, identify_all
from flexcal.calibration.problem import CalibrationProblem
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import standard_trajectory


def test_every_fit_starts_at_the_given_values(monkeypatch):
    """The cross-validation's reference fit on all points (the main fit, its scale being the one
    tried) starts at ``start`` (on the unit box), its held-out fits where it ended, and
    without a start the main fit starts at the prior mean (the paper's model, no prototype:
    the wiring is under test)."""
    space = parameter_space()
    trajectory = standard_trajectory()
    inputs, leg = trajectory.inputs, trajectory.leg
    rng = np.random.default_rng(3)
    x_true = rng.uniform(0.2, 0.8, space.n_params)
    angles = CalibrationProblem(space=space, inputs=inputs, angles=np.zeros_like(inputs)).model_angles(x_true[None])[0][0]
    starts, ends = [], []
    real = estimation.estimate

    def recording(residuals, prior, **kwargs):
        starts.append(kwargs.get("x0"))
        fit = real(residuals, prior, **{**kwargs, "max_evaluations": 2 * (space.n_params + 1)})
        ends.append(fit.x)
        return fit
    monkeypatch.setattr(pipeline, "estimate", recording)
    monkeypatch.setattr(estimation, "estimate", recording)
    start = space.full_values(space.from_unit(x_true))
    identify_all(space, inputs, angles, leg, IdentificationSettings(start=start, n_folds=2, scales=(1.0,)))
    assert len(starts) == 3  # the reference fit (the final one at its scale), two folds
    in_chart = offset_chart(space.names).from_space(x_true)  # the estimator's coordinates
    assert np.allclose(starts[0], in_chart, atol=1e-12)  # unit-box round trip of the SI start
    for x0 in starts[1:]:
        np.testing.assert_array_equal(x0, ends[0])
    starts.clear()
    identify_all(space, inputs, angles, leg, IdentificationSettings(prior_scale=1.0))
    assert starts == [None]  # the prior mean: estimate's own default


def test_verify_refuses_start_with_the_paper_method(tmp_path):
    from flexcal.validation import cli

    assert cli.main(["verify", "--scenario", "table1", "--provider", "analytic", "--method", "paper",
                     "--start", str(tmp_path / "report.json"), "--out", str(tmp_path / "run"), "-q"]) == 2


def test_verify_refuses_a_missing_start_report_before_building_the_model(tmp_path):
    from flexcal.validation import cli

    assert cli.main(["verify", "--scenario", "table1", "--provider", "analytic", "--start", str(tmp_path / "no.json"),
                     "--out", str(tmp_path / "run"), "-q"]) == 2
    assert not (tmp_path / "run").exists()
