"""The mount offsets' Cartesian chart the estimator works in (calibration/offset_chart.py)."""

import numpy as np
import pytest

from flexcal.calibration.offset_chart import offset_chart

NAMES = ("D1.x0", "L1.d", "L1.phi", "L2.w", "L2.d", "L2.phi")


def test_the_chart_renames_each_offset_pair_in_place_and_leaves_the_rest():
    chart = offset_chart(NAMES)
    assert chart.names == ("D1.x0", "L1.dy", "L1.dz", "L2.w", "L2.dy", "L2.dz")
    assert chart.pairs.tolist() == [[1, 2], [4, 5]]
    lone = offset_chart(("L1.d", "D1.x0"))  # a magnitude without its direction is not a pair
    assert lone.names == ("L1.d", "D1.x0") and lone.pairs.shape == (0, 2)
    Y = np.random.default_rng(0).random((5, 2))
    np.testing.assert_array_equal(lone.to_space(Y), Y)


def test_the_unit_box_maps_one_to_one_onto_the_disc_of_the_papers_range():
    """Every chart point is an offset within d_max (|unit magnitude| <= 1: a report's values stay
    inside the bounds); the round trip space -> chart -> space and back is exact to round-off;
    the other sources pass through unchanged."""
    chart = offset_chart(NAMES)
    rng = np.random.default_rng(1)
    Y = rng.random((4000, 6))
    X = chart.to_space(Y)
    assert X[:, [1, 4]].max() <= 1.0 + 1e-12  # the disc; round-off
    assert X[:, [2, 5]].min() >= 0.0 and X[:, [2, 5]].max() < 1.0  # a direction in [0, 2 pi)
    np.testing.assert_array_equal(X[:, [0, 3]], Y[:, [0, 3]])
    np.testing.assert_allclose(chart.from_space(X), Y, atol=1e-12)  # round-off of the closed-form inverse
    Xs = rng.random((4000, 6))
    np.testing.assert_allclose(chart.to_space(chart.from_space(Xs)), Xs, atol=1e-12)  # the same, other way round


def test_near_zero_offset_the_coordinates_are_the_offsets_components():
    """Identity to first order at the origin: a small offset d (cos phi, sin phi) sits at
    0.5 + d (cos phi, sin phi) / (2 d_max) in the chart, to O(d^3); the origin is 0.5, 0.5."""
    chart = offset_chart(("L1.d", "L1.phi"))
    for r in (1e-2, 1e-3):
        phi = 2.2
        y = chart.from_space(np.array([r, phi / (2 * np.pi)]))
        expected = 0.5 + 0.5 * r * np.array([np.cos(phi), np.sin(phi)])
        assert np.abs(y - expected).max() < r ** 3  # the map's cubic term (coefficient <= 1/4 of r^3)
    np.testing.assert_allclose(chart.from_space(np.array([0.0, 0.3])), [0.5, 0.5], atol=0)  # exact


def test_the_jacobian_and_the_delta_method_bars():
    """dX/dY against central differences (step 1e-6: error ~1e-11 relative); at zero offset the
    direction's rows are infinite, and so is its delta-method variance; away from it the
    transformed covariance is J C J^T."""
    chart = offset_chart(NAMES)
    rng = np.random.default_rng(2)
    for _ in range(20):
        y = 0.15 + 0.7 * rng.random(6)
        J = chart.jacobian(y)
        h = 1e-6
        numeric = np.array([(chart.to_space(y + h * e) - chart.to_space(y - h * e)) / (2 * h) for e in np.eye(6)]).T
        if np.abs(numeric[[2, 5]]).max() > 10:  # a difference across the direction's cut at 0 / 2 pi
            continue
        np.testing.assert_allclose(J, numeric, atol=1e-7 * np.abs(J).max())  # central differences' error
    y0 = np.array([0.3, 0.5, 0.5, 0.4, 0.6, 0.45])
    C = np.diag([1e-4, 4e-4, 4e-4, 1e-4, 4e-4, 1e-4])
    out = chart.covariance_to_space(y0, C)
    assert np.isinf(out[1, 1]) and np.isinf(out[2, 2])  # L1 at zero offset: no direction, no magnitude slope
    J = chart.jacobian(y0)
    np.testing.assert_allclose(out[3:, 3:], J[3:] @ C @ J[3:].T, rtol=1e-12)  # the same products; round-off


def test_identify_all_estimates_in_the_chart_and_reports_polar_bars():
    """Wiring, on the paper's model and its own curve (no prototype): the base parameters are
    named in the chart, the estimate's x is the chart's, x_unit the space's, and the sources' d /
    phi bars are the delta method of the chart's covariance."""
    from flexcal.calibration.pipeline import IdentificationSettings, identify_all
    from flexcal.calibration.problem import CalibrationProblem
    from flexcal.model.parameters import parameter_space
    from flexcal.model.trajectory import standard_trajectory

    space = parameter_space()
    trajectory = standard_trajectory()
    x_true = np.random.default_rng(4).uniform(0.2, 0.8, space.n_params)
    problem = CalibrationProblem(space=space, inputs=trajectory.inputs, angles=np.zeros_like(trajectory.inputs))
    angles = problem.model_angles(x_true[None])[0][0] + np.random.default_rng(5).normal(0, 5e-7, trajectory.inputs.shape)
    found = identify_all(space, trajectory.inputs, angles, trajectory.leg,
                         IdentificationSettings(prior_scale=1.0, noise=5e-7))
    chart = found.chart
    assert "L1.dy" in chart.names and "L1.d" not in chart.names
    assert set(found.base.base) <= set(chart.names)
    np.testing.assert_allclose(found.x_unit, chart.to_space(found.estimate.x), atol=0)  # the same function
    unit = np.sqrt(np.diag(chart.covariance_to_space(found.estimate.x, found.estimate.covariance)))
    ranges = space.upper - space.lower
    index = {n: i for i, n in enumerate(space.names)}
    for name in ("L1.d", "L1.phi", "D1.x0"):
        i = index[name]
        assert found.std[space.active_indices[i]] == pytest.approx(unit[i] * ranges[i], rel=1e-12)  # round-off
