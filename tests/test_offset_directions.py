"""Mount offsets whose direction the data do not determine (calibration/offset_directions.py):
the rule on the sources' table, and the verify report's base table in the estimator's Cartesian
chart (calibration/offset_chart.py), where no combination holds a direction."""

from types import SimpleNamespace

import numpy as np

from flexcal.calibration.offset_directions import UNDETERMINED_SIGMAS, undetermined_directions


def test_a_direction_is_undetermined_when_its_offset_is_within_two_standard_errors_of_zero():
    names = ["L1.d", "L1.phi", "L2.d", "L2.phi", "L3.d", "L3.phi", "D1.x0"]
    values = np.array([0.918e-3, 4.16, 1.2e-3, 3.5, 0.3e-3, 1.0, 0.2e-3])
    std = np.array([0.522e-3, 0.35, 0.5e-3, 0.4, np.inf, 1.0, 1e-6])  # L3.d: no bar (not seen, no prior)
    found = undetermined_directions(names, values, std)
    # L1: 0.918 < 2 x 0.522 (session 22's paper seed 2, L3 there); L2: 1.2 >= 2 x 0.5; L3: not judged
    assert list(found) == ["L1.phi"]
    assert "L1.d = 0.918 +- 0.522 mm" in found["L1.phi"]
    assert UNDETERMINED_SIGMAS == 2.0
    # at exactly two standard errors the offset is told from zero (the rule is d < 2 sigma)
    assert not undetermined_directions(["X.d", "X.phi"], np.array([1.0e-3, 0.0]), np.array([0.5e-3, 0.1]))
    assert undetermined_directions(["X.d", "X.phi"], np.array([0.999e-3, 0.0]), np.array([0.5e-3, 0.1]))


def test_the_base_table_is_in_the_estimators_chart_with_the_truth_mapped_alike():
    """Three sources, L1.d, L1.phi, D1.x0; the estimator works in (L1.dy, L1.dz, D1.x0)
    (calibration.offset_chart). The base table's rows are combinations of those, estimate and
    bar from the estimate's chart coordinates and covariance, the true value the presets mapped
    by the same chart: no row is left without a z-score, whatever the offset's size."""
    from flexcal.calibration.base_parameters import base_parameters
    from flexcal.calibration.offset_chart import offset_chart
    from flexcal.validation.runs.verify import _base_table

    names = ("L1.d", "L1.phi", "D1.x0")
    chart = offset_chart(names)
    assert chart.names == ("L1.dy", "L1.dz", "D1.x0")
    W = np.array([[100.0, 0.0, 0.0], [0.0, 0.0, 100.0], [0.0, 0.0, 0.0]])  # L1.dz unseen: regrouped
    base = base_parameters(W, chart.names)
    assert base.base == ("L1.dy", "D1.x0")
    space = SimpleNamespace(names=names, active_indices=np.arange(3), to_unit=lambda v: np.asarray(v, float))
    y = np.array([0.52, 0.5, 0.5])  # a small offset along y
    identification = SimpleNamespace(base=base, chart=chart, identifiable=("D1.x0",),
                                     estimate=SimpleNamespace(x=y, covariance=np.diag([1e-4, 0.04, 1e-4])))
    presets = np.array([0.01, 0.5, 0.51])  # unit box: |offset| = 0.01 d_max, pointing along -y
    table = _base_table(identification, space, presets)
    first, second = table["rows"]
    true_dy = chart.from_space(presets)[0]
    assert true_dy < 0.5  # the true offset points along -y
    # (estimate - truth) / sqrt(1e-4), to round-off of the chart's inverse map
    assert abs(first["z_score"] - (0.52 - true_dy) / 0.01) < 1e-9
    assert abs(second["z_score"] - (0.5 - 0.51) / 0.01) < 1e-9  # a source alone: its own unit coordinate; round-off
    assert table["n_z_scores"] == 2 and table["pure"] == ["D1.x0"]
