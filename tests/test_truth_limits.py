"""What the truth writes, flexcal reads back (one set of file limits,
flexcal.validation.measurement_limits); a payload or an input the mount cannot take is
named with its figure instead of "Newton did not converge"."""

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flexcal.validation import cli
from flexcal.validation.measurement_limits import MAX_ABS_ANGLE_URAD, sensor_problem
from flexcal.validation.measurements import Measurement, read_measurement, write_measurement

_SHORT = np.array([[0.0, 0.0, 0.0], [0.5e-3, 0.0, 0.0], [0.0, 0.5e-3, 0.0], [0.0, 0.0, 0.3e-3], [0.0, 0.0, 0.0]])


@pytest.fixture(scope="module")
def short_scenario():
    from flexcal.validation.prototype.scenario import load_scenario

    return dataclasses.replace(load_scenario("table1"), inputs=_SHORT, leg=np.array([0, 1, 2, 3, 3]))


_channel = st.floats(0.0, 2e5, allow_nan=False)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(noise=st.tuples(_channel, _channel, _channel), offset=st.tuples(*[st.floats(-2e5, 2e5)] * 3))
def test_anything_the_truth_writes_is_read_back(tmp_path_factory, short_scenario, noise, offset):
    """Sensors the truth accepts give a file the reader reads (the same numbers); sensors
    it refuses are refused before the prototype is built."""
    from flexcal.validation.prototype import truth as truth_module
    from flexcal.validation.prototype.providers import stiffness_provider

    scenario = dataclasses.replace(short_scenario, noise=np.array(noise) * 1e-6, offset=np.array(offset) * 1e-6)
    if sensor_problem(noise, offset) is not None:
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(truth_module, "build_prototype", lambda *a, **k: pytest.fail("computed before refusing"))
            with pytest.raises(ValueError, match="exceeds"):
                truth_module.make_truth(scenario, stiffness_provider("analytic"))
        return
    measurement = truth_module.make_truth(scenario, stiffness_provider("analytic")).measurement
    path = tmp_path_factory.mktemp("truth") / "curves.csv"
    write_measurement(path, measurement)
    back = read_measurement(path)
    np.testing.assert_allclose(back.angles, measurement.angles, atol=1e-12)  # written to 1 prad


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(angle_urad=st.floats(-3e5, 3e5), input_mm=st.floats(-300.0, 300.0))
def test_the_writer_never_writes_what_the_reader_refuses(tmp_path_factory, angle_urad, input_mm):
    n = 3
    measurement = Measurement(point=np.arange(1, n + 1), time=np.arange(n) * 1.0, leg=np.ones(n, int),
                              inputs=np.full((n, 3), input_mm * 1e-3), angles=np.full((n, 3), angle_urad * 1e-6))
    path = tmp_path_factory.mktemp("w") / "curves.csv"
    try:
        write_measurement(path, measurement)
    except ValueError as error:
        assert "not written" in str(error) and not path.exists()
        return
    np.testing.assert_allclose(read_measurement(path).angles, measurement.angles, atol=1e-12)  # 1 prad


def test_truth_refuses_noise_the_reader_would_refuse_before_computing(tmp_path, capsys):
    """The issue's case: --noise-urad 1e6 wrote a curves.csv that verify then refused."""
    status = cli.main(["truth", "--scenario", "table1", "--provider", "analytic", "--noise-urad", "1e6",
                       "--out", str(tmp_path / "t"), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and "noise 1e+06 urad exceeds" in err[0]
    assert not (tmp_path / "t").exists()
    assert sensor_problem(0.5, 0.0) is None and sensor_problem(0.0, MAX_ABS_ANGLE_URAD) is not None


def test_a_payload_the_mount_cannot_hold_is_named_with_the_figure(tmp_path, capsys):
    scenario = tmp_path / "heavy.toml"
    scenario.write_text('name = "heavy"\nseed = 1\n[mechanism]\npayload_mass_kg = 1e5\n')
    status = cli.main(["truth", "--scenario", str(scenario), "--provider", "analytic", "--out", str(tmp_path / "t"),
                       "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1
    assert "payload of 100000 kg is more than this mount holds" in err[0] and "payload_mass_kg" in err[0]
    assert "SolverSettings" not in err[0]
    figure = float(err[0].split("no equilibrium above ")[1].split(" kg")[0])
    assert 1e4 < figure < 5e4  # measured 2.48e4 kg with the analytic segments (it holds 20 t, not 30 t)


def test_an_input_beyond_the_stroke_is_named_with_its_row_and_limit(tmp_path, capsys):
    trajectory = tmp_path / "far.csv"
    trajectory.write_text("xa1_mm,xa2_mm,xa3_mm\n0,0,0\n1,0,0\n20,0,0\n")
    status = cli.main(["truth", "--scenario", "table1", "--provider", "analytic", "--trajectory", str(trajectory),
                       "--out", str(tmp_path / "t"), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1
    for words in ("trajectory point 3 (row 4", "xa1 = 20 mm", "x the stroke of D1", "+-0.978 mm"):
        assert words in err[0], (words, err[0])
    assert "Newton" not in err[0]
