"""The estimate's own fit: the cross-validation's reference fit taken as it is when the chosen
scale is its scale, and a fit that stops at its evaluation budget started again
(``calibration.estimation``, ``calibration.pipeline``; docs/calibration.md "Session 34")."""

import numpy as np

import flexcal.calibration.estimation as estimation
import flexcal.calibration.pipeline as pipeline
from flexcal.calibration.estimation import estimate, uniform_prior
from flexcal.calibration.offset_chart import offset_chart
from flexcal.calibration.pipeline import FINAL_BUDGET_RESTARTS, IdentificationSettings, identify_all
from flexcal.calibration.problem import CalibrationProblem
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import WORKSPACE, standard_trajectory


def test_the_reference_fit_is_the_estimate_when_its_scale_is_chosen(monkeypatch):
    """With one scale (so the reference's is chosen), identify_all fits once on all points, not
    twice, and its estimate is the one a fit of its own gives, to the bit (the paper's model on
    the standard trajectory, noise-free: the wiring is under test, so each fit gets a small
    budget)."""
    from flexcal.model import kernel

    kernel.available()  # numba loaded first: "auto" then runs every call compiled (model.forward.resolve_engine)
    space = parameter_space()
    trajectory = standard_trajectory()
    inputs, leg = trajectory.inputs, trajectory.leg
    x_true = np.random.default_rng(4).uniform(0.2, 0.8, space.n_params)
    angles = CalibrationProblem(space=space, inputs=inputs, angles=np.zeros_like(inputs)).model_angles(x_true[None])[0][0]
    budget = 3 * (space.n_params + 2)  # three Jacobians' worth: a few steps each
    calls = []
    real = estimation.estimate

    def small(residuals, prior, **kwargs):
        calls.append(kwargs.get("max_evaluations"))
        return real(residuals, prior, **{**kwargs, "max_evaluations": kwargs.get("max_evaluations") or budget})
    monkeypatch.setattr(pipeline, "estimate", small)
    monkeypatch.setattr(estimation, "estimate", small)
    result = identify_all(space, inputs, angles, leg, IdentificationSettings(n_folds=2, scales=(1.0,), staged=False))
    assert result.prior_scale == 1.0
    assert len(calls) == 3  # the reference fit and two folds; no fit of its own
    chart = offset_chart(space.names)
    problem = CalibrationProblem(space=space, inputs=inputs, angles=angles)
    own = real(lambda Y: problem.residuals(chart.to_space(Y)), uniform_prior(space.n_params, 1.0),
               max_evaluations=budget, coordinates=angles / WORKSPACE, budget_restarts=FINAL_BUDGET_RESTARTS)
    for name in ("x", "std", "covariance", "residual"):
        np.testing.assert_array_equal(getattr(result.estimate, name), getattr(own, name), err_msg=name)
    assert result.estimate.noise == own.noise and result.estimate.discrepancy is not None


def _valley(X):
    """A curved valley (Rosenbrock's, moved into the unit box): minimum 0 at (0.5, 0.5)."""
    X = np.atleast_2d(X)
    return np.stack([10.0 * (X[:, 1] - X[:, 0] ** 2 - 0.25), 0.5 - X[:, 0]], axis=1)


def test_a_fit_stopped_at_its_budget_starts_again_until_it_converges():
    """Along a curved valley from (0.05, 0.95) trust-region steps stay short: 6 rows (2
    Jacobians' worth) stop the fit on the way (0.08 from the minimum, measured); with restarts
    from its best point it reaches the minimum, and ``stopped_at_budget`` tells the two apart."""
    prior = uniform_prior(2, np.inf)
    stopped = estimate(_valley, prior, noise=1.0, x0=np.array([0.05, 0.95]), max_evaluations=6, point_size=1)
    assert stopped.stopped_at_budget
    assert np.abs(stopped.x - 0.5).max() > 1e-2  # far from the minimum when it stopped
    done = estimate(_valley, prior, noise=1.0, x0=np.array([0.05, 0.95]), max_evaluations=6, point_size=1,
                    budget_restarts=40)
    assert not done.stopped_at_budget
    # trf's tolerances (1e-8 on the step and the cost) leave x within ~1e-4 of a zero residual's minimum
    np.testing.assert_allclose(done.x, [0.5, 0.5], atol=1e-4)


def test_the_fold_fits_start_at_the_reference_fit(monkeypatch):
    """Without a given noise the folds' fits start where the fit on all points ended (a held-out
    fit then needs only its own few steps from there, docs/calibration.md "Session 35"); with a
    given noise there is no reference fit and they start at x0. A model linear in its two
    parameters on 12 points of 3 residuals each (the wiring is under test)."""
    rng = np.random.default_rng(7)
    A = rng.normal(size=(12, 3, 2))
    data = A @ np.array([0.3, 0.7]) + 1e-3 * rng.normal(size=(12, 3))

    def residuals_for(points):
        return lambda X: (np.einsum("pkj,nj->npk", A[points], np.atleast_2d(X)) - data[points]).reshape(len(X), -1)

    starts = []
    real = estimation.estimate

    def recording(residuals, prior, **kwargs):
        starts.append(None if kwargs.get("x0") is None else np.array(kwargs["x0"]))
        return real(residuals, prior, **kwargs)
    monkeypatch.setattr(estimation, "estimate", recording)
    folds = [np.arange(0, 4), np.arange(4, 8), np.arange(8, 12)]
    x0 = np.array([0.9, 0.1])
    cv = estimation.choose_prior_scale(residuals_for, 2, folds, 12, scales=(1.0, 2.0), x0=x0)
    assert len(starts) == 1 + 2 * 3
    np.testing.assert_array_equal(starts[0], x0)  # the reference fit starts at x0
    for start in starts[1:]:
        np.testing.assert_array_equal(start, cv.reference.x)
    starts.clear()
    cv = estimation.choose_prior_scale(residuals_for, 2, folds, 12, scales=(1.0,), x0=x0, noise=1e-3)
    assert cv.reference is None and len(starts) == 3
    for start in starts:
        np.testing.assert_array_equal(start, x0)


def test_the_estimate_at_another_scale_starts_where_the_reference_fit_ended(monkeypatch):
    """When the cross-validation chooses a scale other than the reference fit's, the estimate
    is a fit of its own on all points, started where the reference fit ended (docs/calibration.md
    "Session 35": on the noise-free README run from the staged start it ended at 0.0020 urad
    RMS, from the reference at 0.0017 in 42 % fewer evaluations). The paper's model, small
    budgets: the wiring is under test."""
    space = parameter_space()
    trajectory = standard_trajectory()
    inputs, leg = trajectory.inputs, trajectory.leg
    x_true = np.random.default_rng(4).uniform(0.2, 0.8, space.n_params)
    angles = CalibrationProblem(space=space, inputs=inputs, angles=np.zeros_like(inputs)).model_angles(x_true[None])[0][0]
    budget = 3 * (space.n_params + 2)
    calls = []
    real = estimation.estimate

    def small(residuals, prior, **kwargs):
        fit = real(residuals, prior, **{**kwargs, "max_evaluations": kwargs.get("max_evaluations") or budget})
        calls.append((kwargs.get("x0"), round(float(prior.std[0] / estimation.UNIFORM_STD), 9), fit.x))
        return fit
    monkeypatch.setattr(pipeline, "estimate", small)
    monkeypatch.setattr(estimation, "estimate", small)
    monkeypatch.setattr(estimation, "one_standard_error_choice", lambda scores, errors: len(scores) - 1)  # the widest
    result = identify_all(space, inputs, angles, leg, IdentificationSettings(n_folds=2, scales=(1.0, 4.0), staged=False))
    assert result.prior_scale == 4.0
    assert len(calls) == 1 + 2 * 2 + 1  # the reference, the folds, the estimate's own fit
    reference_start, reference_scale, reference_end = calls[0]
    assert reference_start is None and reference_scale == 1.0
    last_start, last_scale, last_end = calls[-1]
    assert last_scale == 4.0
    np.testing.assert_array_equal(last_start, reference_end)
    np.testing.assert_array_equal(result.estimate.x, last_end)
