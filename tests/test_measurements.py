"""Measurement file format: lossless round trip, and bad files rejected with row and column."""

import numpy as np
import pytest

from flexcal.validation.measurements import Measurement, read_measurement, write_measurement


def _example(n=5, extras=True):
    rng = np.random.default_rng(0)
    return Measurement(
        point=np.arange(1, n + 1), time=np.arange(n) * 2.0, leg=np.array([1] * 3 + [2] * (n - 3)),
        inputs=rng.uniform(-1.5e-3, 1.5e-3, (n, 3)), angles=rng.uniform(-5e-3, 5e-3, (n, 3)),
        extras={"temperature_c": 20 + rng.uniform(0, 1, n)} if extras else {},
        metadata={"generator": "test", "seed": 0},
    )


def test_round_trip(tmp_path):
    original = _example()
    path = tmp_path / "curves.csv"
    write_measurement(path, original)
    loaded = read_measurement(path)
    # written with 1 pm / 1 prad resolution: a round trip is exact to that rounding
    np.testing.assert_allclose(loaded.inputs, original.inputs, atol=1e-12)
    np.testing.assert_allclose(loaded.angles, original.angles, atol=1e-12)  # as above (1 prad)
    np.testing.assert_array_equal(loaded.point, original.point)
    np.testing.assert_array_equal(loaded.leg, original.leg)
    # written with 9 significant digits (.9g): 5e-9 relative
    np.testing.assert_allclose(loaded.extras["temperature_c"], original.extras["temperature_c"], rtol=1e-8)
    assert loaded.metadata == {"generator": "test", "seed": 0}


def _write_text(tmp_path, text):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    return path


HEADER = "point,time_s,leg,xa1_mm,xa2_mm,xa3_mm,theta_x_urad,theta_y_urad,theta_z_urad"


@pytest.mark.parametrize(
    "body, words",
    [
        ("point,time_s,leg,xa1_mm,xa2_mm,xa3_mm,theta_x_urad,theta_y_urad\n1,0,1,0,0,0,0,0\n", ["row 1", "theta_z_urad"]),
        (HEADER + "\n1,0,1,0,0,0,0,0,0\n2,1,1,0,abc,0,0,0,0\n", ["row 3", "xa2_mm", "'abc'"]),
        (HEADER + "\n1,0,1,0,0,0,0,nan,0\n", ["row 2", "theta_y_urad", "not finite"]),
        (HEADER + "\n1,0,1,0.5,0,0,0,0,0\n1,1,1,0,0,0,0,0,0\n", ["row 3", "'point'", "increase"]),
        (HEADER + "\n1,0,1,1500,0,0,0,0,0\n", ["row 2", "xa1_mm", "mm"]),
        (HEADER + "\n1,0,1,0,0,0,0.004,0,0\n2,0,1,0,0,0,0,0,2e6\n", ["row 3", "theta_z_urad", "microradians"]),
        (HEADER + ",temperature\n1,0,1,0,0,0,0,0,0,20\n", ["temperature", "unit"]),
        (HEADER + "\n1,0,1,0,0,0\n", ["row 2", "6 values"]),
        # time stamps beyond 317 years (MAX_TIME_S): numpy's rates overflowed in diagnose
        (HEADER + "\n1,0,1,0,0,0,0,0,0\n2,1e200,1,0,0,0,0,0,0\n", ["row 3", "'time_s'", "seconds"]),
        (HEADER + "\n", ["no data rows"]),
    ],
)
def test_bad_files_name_row_and_column(tmp_path, body, words):
    with pytest.raises(ValueError) as info:
        read_measurement(_write_text(tmp_path, body))
    for word in words:
        assert word in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_measurement(tmp_path / "nope.csv")
