"""Building blocks of the gap diagnosis (no prototype runs): information criteria, held-out
folds, term fits with test-double terms, noise floor, structure tests."""

import math

import numpy as np
import pytest

from flexcal.validation.diagnosis.where import (autocorrelation, noise_floor_differences, noise_floor_repeats, periodicity, runs_test, strata)
from flexcal.validation.diagnosis.which import (aicc, bic, cross_validate, fit_terms, is_linear, leg_folds, make_problem, principal_cosines)
from flexcal.validation.effects.terms import ModelTerm, TermData


def test_aicc_and_bic_against_hand_values():
    # n = 100, RSS = 50, k = 4: n ln(RSS/n) = 100 ln 0.5 = -69.3147...
    assert aicc(50.0, 100, 4) == pytest.approx(-69.31471805599453 + 8 + 40 / 95, rel=1e-12)
    # hand values to 16 digits: round-off only
    assert bic(50.0, 100, 4) == pytest.approx(-69.31471805599453 + 4 * 4.605170185988092, rel=1e-12)
    with pytest.raises(ValueError, match="n - k - 1"):
        aicc(1.0, 5, 4)


def _two_cycle_legs():
    per_leg = 8
    inputs, legs = [np.zeros((1, 3))], [np.zeros(1, int)]
    for cycle in range(2):
        for k in range(3):
            block = np.zeros((per_leg, 3))
            block[:, k] = np.sin(np.linspace(0.3, 2 * np.pi, per_leg)) * 1e-3
            inputs.append(block)
            legs.append(np.full(per_leg, 1 + k + 3 * cycle))
    return np.concatenate(inputs), np.concatenate(legs)


def test_leg_folds_leave_whole_legs_out():
    from flexcal.model.trajectory import travel_directions

    inputs, leg = _two_cycle_legs()
    folds, unit = leg_folds(leg, inputs, travel_directions(inputs))
    assert unit == "leg" and len(folds) == 6
    for fold, number in zip(folds, range(1, 7)):
        np.testing.assert_array_equal(fold, leg == number)  # exactly one whole leg, never single points
    assert not np.any(np.any(folds, axis=0)[leg == 0])  # the start point is always trained on
    # one cycle: leaving a leg out would leave its actuator unmoved -> contiguous strokes instead
    one = leg <= 3
    folds, unit = leg_folds(leg[one], inputs[one], travel_directions(inputs[one]))
    assert unit == "stroke" and len(folds) >= 6
    for fold in folds:
        index = np.flatnonzero(fold)
        assert len(index) >= 2 and np.all(np.diff(index) == 1)  # contiguous


def test_share_of_held_out_postures_measured_in_no_other_leg():
    """0 when every held-out posture is repeated in the training legs (two cycles), 1 when
    each leg visits its own postures (one pass of a designed trajectory); a posture that a
    leg measures twice in a row is still alone when that leg is held out."""
    from flexcal.model.trajectory import travel_directions
    from flexcal.validation.diagnosis.benchmark import repeated_trajectory
    from flexcal.validation.diagnosis.diagnose import share_not_repeated

    inputs, leg = _two_cycle_legs()
    folds, _ = leg_folds(leg, inputs, travel_directions(inputs))
    assert share_not_repeated(inputs, folds) == 0.0
    postures = np.random.default_rng(0).uniform(-1e-3, 1e-3, size=(12, 3))
    designed = np.vstack([np.zeros((1, 3)), postures[:6], postures[5:6], postures[6:]])  # posture 6 twice in a row
    designed_leg = np.concatenate([[0], np.repeat([1, 2, 3], [4, 5, 4])])
    folds, unit = leg_folds(designed_leg, designed, travel_directions(designed))
    assert unit == "leg" and share_not_repeated(designed, folds) == 1.0
    inputs, leg = repeated_trajectory(2, (designed, designed_leg))
    np.testing.assert_array_equal(leg, np.concatenate([designed_leg, designed_leg[1:] + 3]))
    folds, _ = leg_folds(leg, inputs, travel_directions(inputs))
    assert len(folds) == 6 and share_not_repeated(inputs, folds) == 0.0


def _data(n=120, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    inputs = np.column_stack([np.sin(t / 9), np.cos(t / 13), np.sin(t / 5)]) * 1e-3
    leg = 1 + (np.arange(n) // 20)
    return TermData(inputs=inputs, time=t, leg=leg, direction=np.ones((n, 3)), model_angles=inputs * 2.0,
                    axial_loads=rng.normal(size=(n, 6)) * 100, input_jacobian=np.tile(np.eye(3), (n, 1, 1)))


def _linear_double():  # a drift-like test double: rate per channel [rad/s]
    return ModelTerm(id="ramp", parameter_names=("rx", "ry", "rz"), parameter_units=("rad/s",) * 3,
                     scale=np.full(3, 1e-8), evaluate=lambda p, d: np.outer(d.time, p))


def _nonlinear_double():  # an exponential with amplitude and rate (nonlinear in the rate)
    return ModelTerm(id="decay", parameter_names=("a", "k"), parameter_units=("rad", "1/s"),
                     scale=np.array([1e-6, 1e-2]),
                     evaluate=lambda p, d: np.outer(p[0] * (1 - np.exp(-p[1] * d.time)), np.ones(3)))


def test_term_fit_recovers_a_linear_and_a_nonlinear_double():
    data = _data()
    n = data.inputs.shape[0]
    rng = np.random.default_rng(1)
    baseline = rng.normal(size=(n, 3, 4)) * 1e-6  # 4 baseline directions [rad per unit box]
    true_rate = np.array([2e-8, -1e-8, 3e-8])
    sigma = 0.05e-6
    residual = (np.outer(data.time, true_rate) + baseline @ np.array([0.1, -0.2, 0.0, 0.05])
                + rng.normal(size=(n, 3)) * sigma)
    terms = [_linear_double(), _nonlinear_double()]
    problem = make_problem(residual, np.full(3, sigma), baseline, np.full(4, 1.0), data, terms)
    assert problem.linear == {"ramp": True, "decay": False}
    fit = fit_terms(problem, ["ramp"])
    # 120 points, noise 0.05 urad, time sd 34.6 s: the rate's standard error is
    # 0.05e-6 / (34.6 sqrt 120) = 1.3e-10 rad/s; 5e-10 is ~4 standard errors
    np.testing.assert_allclose(fit.params["ramp"], true_rate, atol=5e-10)
    assert fit.chi2 / fit.n_rows < 1.3  # whitened residual ~ noise (chi2 per row ~ 1)
    residual2 = np.outer(2e-6 * (1 - np.exp(-0.03 * data.time)), np.ones(3)) + rng.normal(size=(n, 3)) * sigma
    problem2 = make_problem(residual2, np.full(3, sigma), baseline, np.full(4, 1e-3), data, terms)
    fit2 = fit_terms(problem2, ["decay"])
    np.testing.assert_allclose(fit2.params["decay"], [2e-6, 0.03], rtol=0.02)  # 2 %: noise / signal ~ 1/40
    # held out by legs: predictions of left-out legs are as good as the noise
    cv = cross_validate(problem, ["ramp"], [data.leg == k for k in range(1, 7)])
    assert np.sqrt(np.nanmean(cv**2)) < 1.5 * sigma  # 1.5: six folds of 20 points, fit error small


def test_linearity_check_and_principal_angles():
    data = _data()
    for term, linear in ((_linear_double(), True), (_nonlinear_double(), False)):
        from flexcal.validation.diagnosis.which import term_columns

        assert is_linear(term, data, term_columns(term, data)) is linear
    A = np.random.default_rng(2).normal(size=(50, 3))
    np.testing.assert_allclose(principal_cosines(A, A @ np.array([[1, 2, 0], [0, 1, 0], [3, 0, 1.0]])), 1.0)
    B = np.linalg.qr(np.random.default_rng(3).normal(size=(50, 6)))[0]
    assert principal_cosines(B[:, :3], B[:, 3:]).max() < 1e-12  # orthogonal complements


def test_noise_floor_on_white_noise():
    """Second-difference MAD estimator: over 400 replicates of 300 points it is unbiased to
    0.5 % with a spread of 8.3 % (measured); at 2000 points the spread is 3.2 %, so 13 % is a
    4-sigma tolerance."""
    sigma = np.array([0.3e-6, 0.5e-6, 1.0e-6])
    rng = np.random.default_rng(11)
    noise = rng.normal(size=(2000, 3)) * sigma
    leg = np.repeat(np.arange(10), 200)
    # 4 sigma of the estimator at 2000 points (docstring)
    np.testing.assert_allclose(noise_floor_differences(noise, leg), sigma, rtol=0.13)
    # on top of a smooth structure 20x the noise (it cancels in second differences)
    t = np.linspace(0, 1, 2000)
    smooth = 20 * sigma * np.column_stack([np.sin(2 * np.pi * t), t**2, np.cos(3 * t)])
    np.testing.assert_allclose(noise_floor_differences(noise + smooth, leg), sigma, rtol=0.13)  # as above
    # repeats: the same 100 inputs visited twice; difference of two readings / sqrt 2
    inputs = np.tile(rng.uniform(-1e-3, 1e-3, (100, 3)), (2, 1))
    angles = rng.normal(size=(200, 3)) * sigma
    estimate, pairs = noise_floor_repeats(angles, inputs, np.ones((200, 3)))
    assert pairs == 100
    np.testing.assert_allclose(estimate, sigma, rtol=0.35)  # 100 pairs: MAD spread ~12 %, 3 sigma


def test_structure_tests_tell_noise_from_structure():
    rng = np.random.default_rng(5)
    white = rng.normal(size=400)
    wave = np.sin(2 * np.pi * np.arange(400) / 40) + 0.1 * white
    assert abs(runs_test(white)) < 3 and runs_test(wave) < -10  # z scores
    assert abs(autocorrelation(white)) < 3 / math.sqrt(400) < autocorrelation(wave)
    found = periodicity(wave)
    # neighbouring periodogram bins are 36.4 and 44.4 points; p: a wave 10x the noise
    assert found["period_points"] == pytest.approx(40, rel=0.05) and found["p_value"] < 1e-6
    # white noise: p is uniform, below 1e-3 for 0.1 % of seeds (this one fixed)
    assert periodicity(white)["p_value"] > 1e-3


def test_strata_cover_the_requested_groupings():
    n = 60
    rng = np.random.default_rng(0)
    inputs = np.column_stack([np.sin(np.arange(n) / 5), np.zeros(n), np.cos(np.arange(n) / 7)]) * 1e-3
    residual = rng.normal(size=(n, 3)) * 1e-6
    residual[:15] *= 10
    rows = strata(residual, leg=np.repeat([1, 2, 3], 20), direction=np.sign(np.gradient(inputs, axis=0)) + (
        np.gradient(inputs, axis=0) == 0), point_class=["S1"] * 30 + ["S2"] * 30, time=np.arange(n, dtype=float),
        inputs=inputs, extras={"temperature_c": np.linspace(20, 21, n)})
    kinds = {r["by"] for r in rows}
    for kind in ("leg", "point class", "time [s]", "position D1 [mm]", "screw phase D1 [deg]",
                 "temperature [degC]", "direction D1"):
        assert kind in kinds
    first_leg = next(r for r in rows if r["by"] == "leg" and r["stratum"] == "1")
    assert first_leg["rms_urad"][0] > 3 * next(r for r in rows if r["by"] == "leg" and r["stratum"] == "3")["rms_urad"][0]


def test_baseline_escapes_the_false_clearance_mode():
    """A single 80 x 60 swarm on this `none` file (table1 draw 1000) can end in a
    false clearance mode: a ~100 urad spike at a stroke end (measured 2026-11-22). The
    default baseline (best of several starts after the 45-source polish) must not; its good
    mode leaves ~2.4 urad at most (noise 0.5 urad plus the model gap)."""
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.diagnosis.baseline import BaselineSettings, calibrate_baseline
    from flexcal.validation.diagnosis.benchmark import benchmark_measurement

    measurement = benchmark_measurement("none", 0.0, 0, stiffness_provider("analytic", progress=False)).measurement

    def worst(settings, rng):
        fit = calibrate_baseline(measurement, rng=rng, settings=settings)
        return np.abs(measurement.angles - fit.model_angles).max()

    # which swarm seed lands in the false mode depends on the numerical libraries' build
    # (2026-11-22: seed 0; 2026-11-23, fresh install: seeds 0-4 find the good mode at 2.2-2.3
    # urad, seed 5 the false one at 51 urad): take the first of seeds 0-7 that does
    false = next((rng for rng in range(8) if worst(BaselineSettings(starts=1), rng) > 30e-6), None)
    assert false is not None, "no single start of seeds 0-7 exercises the false mode on this file any more"
    assert worst(BaselineSettings(), false) < 5e-6  # 2x the good mode's 2.4 urad, 1/10 of the false one


def _lookalike_problem():
    data = _data()
    n = data.inputs.shape[0]
    rng = np.random.default_rng(4)
    baseline = rng.normal(size=(n, 3, 4)) * 1e-6
    sigma = 0.05e-6
    residual = np.outer(data.time, [2e-8, -1e-8, 3e-8]) + rng.normal(size=(n, 3)) * sigma
    offset = ModelTerm(id="offset", parameter_names=("ox", "oy", "oz"), parameter_units=("rad",) * 3,
                       scale=np.full(3, 1e-6), evaluate=lambda p, d: np.tile(p, (d.inputs.shape[0], 1)))
    terms = [_linear_double(), _nonlinear_double(), offset]
    problem = make_problem(residual, np.full(3, sigma), baseline, np.full(4, 1.0), data, terms)
    return problem, [data.leg == k for k in range(1, 7)]


@pytest.mark.parametrize("ids", [[], ["ramp"], ["ramp", "offset"]])
def test_batched_heldout_fits_equal_the_looped_ones(ids):
    """heldout_linear (one solve per fold for many residuals) == cross_validate per residual."""
    import dataclasses

    from flexcal.validation.diagnosis.separation import heldout_linear

    problem, folds = _lookalike_problem()
    residuals = np.random.default_rng(5).normal(size=(4, *problem.residual.shape)) * 1e-6
    batched = heldout_linear(problem, ids, folds, residuals)
    looped = np.stack([cross_validate(dataclasses.replace(problem, residual=r), ids, folds) for r in residuals])
    # the same least squares, solved with 4 right-hand sides at once: round-off apart
    np.testing.assert_allclose(batched, looped, rtol=1e-9, atol=1e-9 * np.abs(looped).max())
    with pytest.raises(ValueError, match="linear terms"):
        heldout_linear(problem, ["decay"], folds, residuals)


@pytest.mark.parametrize("winner", ["ramp", "decay"])
def test_lookalike_closures_equal_the_plain_loop(winner):
    """The batched look-alike test gives the closures of the plain loop it replaced (one
    synthetic residual at a time, the same seeded draws in the same order)."""
    import dataclasses

    from flexcal.validation.diagnosis.separation import _baseline_residualized, _closure, lookalike_closures

    problem, folds = _lookalike_problem()
    others = [t for t in problem.terms if t != winner]
    size, draws = 3.0, 2
    if winner == "decay":  # nonlinear: 5 least-squares starts per fold and residual; 3 folds, 1 draw
        folds, draws = [folds[0] | folds[1], folds[2] | folds[3], folds[4] | folds[5]], 1
    rng, expected = np.random.default_rng(0), {}
    for other in others:  # the loop as it stood before the batching
        columns, best = problem.columns[other], -np.inf
        for _ in range(draws):
            signature = _baseline_residualized(problem, columns @ rng.normal(size=columns.shape[-1]))
            rms = float(np.sqrt(np.mean((signature / problem.sigma) ** 2)))
            if not rms > 0:  # a shape the baseline mimics whole: no residual to scale
                continue
            synthetic = dataclasses.replace(problem, residual=signature * (size / rms)
                                            + rng.normal(size=signature.shape) * problem.sigma)
            before = np.nanmean(cross_validate(synthetic, [], folds) ** 2, axis=0)
            after = np.nanmean(cross_validate(synthetic, [winner], folds) ** 2, axis=0)
            best = max(best, _closure(before, after, problem.sigma))
        if np.isfinite(best):
            expected[other] = best
    closures = lookalike_closures(problem, winner, others, folds, size, draws=draws, seed=0)
    assert closures.keys() == expected.keys()
    assert "offset" in expected  # (decay's columns at zero are zero: nothing of its shape to draw)
    for other in expected:  # closures are ratios of mean squares: round-off apart
        # 1e-9 / 1e-12: ratios of mean squares from the same fits, batched or looped (round-off)
        assert closures[other] == pytest.approx(expected[other], rel=1e-9, abs=1e-12), other


def test_the_ridge_solver_equals_the_augmented_least_squares():
    """fit_terms' factor-once solver == numpy's least squares on [A; diag(1/prior)] [b; 0],
    on a baseline with two nearly collinear columns (condition ~1e6) and a weak prior."""
    from flexcal.validation.diagnosis.which import _ridge_solver

    rng = np.random.default_rng(6)
    A = rng.normal(size=(300, 8))
    A[:, 7] = A[:, 6] + 1e-6 * rng.normal(size=300)
    prior = np.full(8, 100.0)
    solve = _ridge_solver(A, prior)
    for b in rng.normal(size=(3, 300)):
        expected = np.linalg.lstsq(np.vstack([A, np.diag(1 / prior)]), np.concatenate([b, np.zeros(8)]),
                                   rcond=None)[0]
        # both backward stable; condition ~1e6 times round-off 1e-16, with room
        np.testing.assert_allclose(solve(b), expected, rtol=1e-8, atol=1e-8 * np.abs(expected).max())


def test_a_nonlinear_winner_is_screened_at_its_fitted_parameters():
    """The look-alike test skips effects whose signature space barely meets the winner's. A
    nonlinear winner (amplitudes times a shape with a free rate, as sensor_settling and creep)
    has zero columns at zero parameters, so screened there it met no effect, none was tried and
    the winner counted as separated without a test (sensor_settling's `high` on the designed
    trajectory, docs/diagnosis.md session 17). Screened at its fitted parameters, a ramp (which
    the slow exponential imitates) is tried, and the winner is not separated from it."""
    from flexcal.validation.diagnosis.diagnose import _collinearity
    from flexcal.validation.diagnosis.separation import SKIP_COSINE, fitted_cosines, separation

    data = _data()
    n = data.inputs.shape[0]
    rng = np.random.default_rng(7)
    lag = ModelTerm(id="lag", parameter_names=("ax", "ay", "az", "k"), parameter_units=("rad",) * 3 + ("1/s",),
                    scale=np.array([1e-6, 1e-6, 1e-6, 1e-2]),
                    evaluate=lambda p, d: np.outer(1 - np.exp(-p[3] * d.time), p[:3]))
    sigma = 0.05e-6
    residual = np.outer(1 - np.exp(-0.01 * data.time), [2e-6, -1e-6, 1.5e-6]) + rng.normal(size=(n, 3)) * sigma
    problem = make_problem(residual, np.full(3, sigma), rng.normal(size=(n, 3, 4)) * 1e-6, np.full(4, 1.0), data,
                           [_linear_double(), lag])
    at_zero = _collinearity(problem, ["ramp", "lag"])["max_principal_cosine"]["lag"]
    assert at_zero["ramp"] == 0.0  # the amplitude 0 hides the shape: the screen at zero sees nothing
    fitted = fitted_cosines(problem, "lag", fit_terms(problem, ["lag"]).params["lag"])
    assert fitted["ramp"] > SKIP_COSINE  # 1 - exp(-0.01 t) over t = 0..119 s is mostly a ramp
    folds = [data.leg <= 2, (data.leg == 3) | (data.leg == 4), data.leg >= 5]  # 3 folds: fewer nonlinear fits
    result = separation(problem, "lag", ["lag"], folds, 0.7, at_zero)
    assert result["screen"] == "fitted"
    assert "ramp" in result["closures"]  # tried (skipped before: closures {}, separated True)
    assert not result["separated"] and result["closest"] == "ramp", result
