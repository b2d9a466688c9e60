"""Mount offsets whose direction the data do not determine (calibration/offset_directions.py):
the rule, and the verify report's base table leaving their combinations out of the z-scores."""

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


def test_the_base_table_leaves_a_combination_led_by_an_undetermined_direction_out_of_the_z_scores():
    """Three sources on the unit box; the base combinations are L1.phi (led by the direction of an
    offset 0.5 +- 0.4 mm: undetermined) and D1.x0 alone. The first row says why and has no z-score;
    z_rms is the second row's alone."""
    from flexcal.calibration.base_parameters import base_parameters
    from flexcal.validation.runs.verify import _base_table, _undetermined

    names = ("L1.d", "L1.phi", "D1.x0")
    W = np.array([[0.0, 100.0, 0.0], [0.0, 0.0, 100.0], [0.0, 0.0, 0.0]])  # L1.d unseen: regrouped
    base = base_parameters(W, names)
    assert base.base == ("L1.phi", "D1.x0")
    space = SimpleNamespace(names=names, parameters=[SimpleNamespace(name=n) for n in names],
                            active_indices=np.arange(3), to_unit=lambda v: np.asarray(v, float))
    identification = SimpleNamespace(base=base, x_unit=np.array([0.25, 0.7, 0.5]),
                                     estimate=SimpleNamespace(covariance=np.diag([0.04, 1e-4, 1e-4])),
                                     values=np.array([0.5e-3, 4.4, 0.2e-3]), std=np.array([0.4e-3, 0.06, 1e-6]))
    undetermined = _undetermined(space, identification.values, identification.std, selected=names)
    table = _base_table(identification, space, np.array([0.25, 0.3, 0.51]), undetermined)
    first, second = table["rows"]
    assert "undetermined" in first and first["z_score"] is None and "L1.d = 0.5 +- 0.4 mm" in first["undetermined"]
    assert second["z_score"] == (0.5 - 0.51) / 0.01  # (estimate - truth) / sqrt(1e-4)
    assert table["n_z_scores"] == 1 and table["z_rms"] == abs(second["z_score"])
    assert list(table["undetermined_directions"]) == ["L1.phi"]
