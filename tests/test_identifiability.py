"""Identifiability: rank, conditioning, confounded groups, parameter uncertainty."""

from __future__ import annotations

import numpy as np
import pytest

from flexcal.calibration import testfunctions as tf
from flexcal.calibration.identifiability import analyze_jacobian, identifiability


def test_well_posed_jacobian():
    J = np.random.default_rng(0).normal(size=(50, 5))
    report = analyze_jacobian(J, list("abcde"))
    assert report.rank == 5 and report.groups == ()
    # both from the singular values: round-off only
    assert report.condition_number == pytest.approx(np.linalg.cond(J), rel=1e-12)
    assert report.meaningful.all()
    assert set(report.identifiable) == set("abcde")


def test_duplicated_parameter_is_detected():
    rng = np.random.default_rng(1)
    a, b, c = rng.normal(size=(3, 40))
    J = np.column_stack([a, b, c, a])  # d duplicates a
    report = analyze_jacobian(J, ["a", "b", "c", "d"])
    assert report.rank == 3
    # exact duplicate: sigma_min is round-off, cond measured 9e15 (or inf)
    assert report.condition_number == np.inf or report.condition_number > 1e12
    assert report.groups == (("a", "d"),)
    assert report.meaningful.tolist() == [False, True, True, False]
    assert len(set(report.identifiable) & {"a", "d"}) == 1  # the pivoting keeps one of them
    assert report.max_cosine[0] == pytest.approx(1.0)


def test_collinear_combination_groups_all_three():
    rng = np.random.default_rng(2)
    a, b, e = rng.normal(size=(3, 40))
    J = np.column_stack([a, b, 2 * a - b, e])
    report = analyze_jacobian(J, ["a", "b", "c", "e"])
    assert report.rank == 3
    assert report.groups == (("a", "b", "c"),)
    assert report.meaningful.tolist() == [False, False, False, True]


def test_noise_scaling_gives_the_least_squares_covariance():
    rng = np.random.default_rng(3)
    J = rng.normal(size=(60, 4)) * [1000.0, 500.0, 200.0, 5.0]
    sigma = 2.0
    report = analyze_jacobian(J, list("abcd"), noise=sigma, max_std=0.01)
    expected = np.sqrt(np.diag(np.linalg.inv(J.T @ J))) * sigma
    # round-off bound eps cond(J^T J) ~ 1e-11 (columns scaled 5..1000); measured 6e-16
    np.testing.assert_allclose(report.parameter_std, expected, rtol=1e-10)
    # d's column is ~5/sigma * sqrt(60) ~ 19 noise units per range: std ~0.05 > 0.01
    assert report.meaningful.tolist() == [True, True, True, False]
    assert report.groups == (("d",),)


def test_from_residuals_insensitive_parameters_are_not_meaningful():
    problem = tf.curve_fit_problem(20, n_insensitive=3, noise=1.0)
    report = identifiability(problem.residuals, problem.x_true, problem.names, noise=1.0)
    # noise-free rank is full (the weak ones are 1000x weaker, not absent) ...
    assert report.rank == 20
    # ... but with a noise of 1 the three weak parameters are pinned down worse than 1 %
    assert set(report.meaningful_names) == set(np.array(problem.names)[problem.sensitive])
    # measured 5-8 ranges for the weak three (< 0.01 for the others)
    assert all(report.parameter_std[~problem.sensitive] > 1.0)
    assert "cannot tell apart" in report.summary()


def test_from_residuals_a_duplicated_parameter_is_found():
    base = tf.curve_fit_problem(12, n_insensitive=0)

    def residuals(x):  # the model only sees x0_1 + extra: extra is a duplicate of x0_1
        x = np.atleast_2d(x)
        merged = x[:, :12].copy()
        merged[:, 0] = 0.5 * (x[:, 0] + x[:, 12])
        return base.residuals(merged)

    names = list(base.names) + ["extra"]
    x = np.append(base.x_true, base.x_true[0])
    report = identifiability(residuals, x, names)
    assert report.rank == 12
    assert ("x0_1", "extra") in report.groups
    assert not report.meaningful[0] and not report.meaningful[-1]
    assert report.meaningful[1:12].all()
