"""Typed input files (issue 23): scenario and config TOML, measurement sidecar JSON and
trajectory CSV are checked against one schema each (msgspec); a wrong type, an unknown
key, a foreign encoding or an oversized file is one line naming the file, the key, what
was expected and the value given."""

import json
import logging
import subprocess
import sys

import numpy as np
import pytest

from flexcal.validation import cli
from flexcal.validation.measurements import Measurement, read_measurement, write_measurement
from flexcal.validation.prototype.scenario import load_scenario, mechanism_from_metadata, read_trajectory


def refusal(call, *args) -> str:
    with pytest.raises(ValueError) as info:
        call(*args)
    message = str(info.value)
    assert "\n" not in message  # one line
    return message


def scenario_file(tmp_path, text: str, name: str = "s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, words", [
    # used to run as seed 1 (int(1.7))
    ('seed = 1.7\n', ["seed = 1.7", "must be an integer", "decimal number"]),
    # used to be read as true (a non-empty string)
    ('draw_unset = "no"\n', ['draw_unset = "no"', "must be a boolean", "string"]),
    # used to end in exit 1, "TypeError: 'int' object is not iterable"
    ('errors = 3\n', ["errors = 3", "must be a table", "integer"]),
    ('[mechanism]\ncentre_of_gravity_mm = [1, 2]\n', ["mechanism.centre_of_gravity_mm = [1, 2]", "length 3"]),
    ('[mechanism]\ncolour = "red"\n', ["unknown key 'mechanism.colour'", '"red"', "centre_of_gravity_mm"]),
    ('[trajectory]\ndwell_s = nan\n', ["trajectory.dwell_s = NaN"]),
    ('[errors]\n"D1.CL" = "0.2"\n', ['errors."D1.CL" = "0.2"', "must be a number", "string"]),
    ('[[effects]]\nname = "drift"\nseed = 2.5\n', ["effects[0].seed = 2.5", "must be an integer"]),
], ids=["seed-float", "draw_unset-string", "errors-int", "cog-two", "unknown-key", "dwell-nan", "error-string",
        "effect-seed-float"])
def test_scenario_wrong_types_name_file_key_and_value(tmp_path, text, words):
    path = scenario_file(tmp_path, 'name = "x"\n' + text)
    message = refusal(load_scenario, str(path))
    for word in [str(path), *words]:
        assert word in message, (word, message)


@pytest.mark.parametrize("n_points", [100_001, 100_000_001])
def test_scenario_n_points_is_bounded_before_any_work(tmp_path, n_points):
    # 100000001 points used to be accepted and walked (~30 ms a point with the analytic
    # provider: about a month); 100001 is the smallest standard length above the bound
    path = scenario_file(tmp_path, f'name = "x"\n[trajectory]\nn_points = {n_points}\n')
    message = refusal(load_scenario, str(path))
    assert f"trajectory.n_points = {n_points} must be an integer <= 100000" in message and str(path) in message


def test_scenario_in_latin1_names_file_and_line(tmp_path):
    path = tmp_path / "s.toml"
    path.write_bytes('name = "x"\n# café\n'.encode("latin-1"))
    message = refusal(load_scenario, str(path))
    assert str(path) in message and "not UTF-8" in message and "line 2" in message


def test_scenario_larger_than_the_bound_is_refused_unread(tmp_path, monkeypatch):
    import flexcal.geometry.schema as schema

    path = scenario_file(tmp_path, 'name = "x"\n' + "# padding\n" * 200)

    def no_reading(*args, **kwargs):
        raise AssertionError("the file was opened although its size was over the bound")

    monkeypatch.setattr(schema, "MAX_SETTINGS_BYTES", 1000)
    monkeypatch.setattr(type(path), "open", no_reading)
    message = refusal(load_scenario, str(path))
    assert str(path) in message and "1,000 bytes" in message


def test_valid_scenario_loads_as_before(tmp_path):
    path = scenario_file(tmp_path, 'name = "mine"\nseed = 3\n[sensors]\nnoise_urad = 1\noffset_urad = [0, 1, 2]\n'
                                   '[mechanism]\ncentre_of_gravity_mm = [0, 0, 0]\npayload_mass_kg = 250\n'
                                   '[trajectory]\nn_points = 13\ndwell_s = 1\n'
                                   '[[effects]]\nname = "drift"\nrate = [5e-8, 5e-8, 1.5e-7]\n')
    scenario = load_scenario(str(path))
    assert scenario.name == "mine" and scenario.seed == 3 and scenario.inputs.shape == (13, 3)
    np.testing.assert_array_equal(scenario.noise, [1e-6] * 3)
    np.testing.assert_array_equal(scenario.offset, [0.0, 1e-6, 2e-6])
    assert scenario.dwell == 1.0 and isinstance(scenario.dwell, float)
    assert scenario.space.mechanism.centre_of_gravity == (0.0, 0.0, 0.0)
    assert scenario.space.mechanism.payload_mass == 250.0
    assert scenario.effects == ({"name": "drift", "rate": [5e-8, 5e-8, 1.5e-7]},)


# --- the measurement sidecar ------------------------------------------------------------

def measurement(n: int, metadata: dict) -> Measurement:
    k = np.arange(n)
    return Measurement(point=k + 1, time=k * 2.0, leg=np.ones(n, int), inputs=np.zeros((n, 3)) + 1e-4,
                       angles=np.zeros((n, 3)) + 1e-6, extras={}, metadata=metadata)


def test_sidecar_point_count_must_match_the_rows(tmp_path):
    # used to load silently: a sidecar of 12 points beside a 77-row curve
    path = tmp_path / "curves.csv"
    write_measurement(path, measurement(77, {"generator": "test", "n_points": 12}))
    message = refusal(read_measurement, path)
    assert str(path.with_suffix(".json")) in message and "n_points = 12" in message and "77 data rows" in message


@pytest.mark.parametrize("metadata, words", [
    ({"seed": 1.7}, ["seed = 1.7", "must be an integer"]),
    ({"mechanism": {"centre_of_gravity_mm": "abc"}}, ['mechanism.centre_of_gravity_mm = "abc"', "must be a list"]),
    ({"preset_errors": 5}, ["preset_errors = 5", "must be a list"]),
    ({"sensors": {"noise_urad": [0.5, 0.5]}}, ["sensors.noise_urad = [0.5, 0.5]", "length 3"]),
    ({"operator": "me"}, ["unknown key 'operator'", "notes"]),
], ids=["seed-float", "cog-string", "presets-int", "noise-two", "unknown-key"])
def test_sidecar_wrong_types_name_file_key_and_value(tmp_path, metadata, words):
    path = tmp_path / "curves.csv"
    write_measurement(path, measurement(5, metadata))
    message = refusal(read_measurement, path)
    for word in [str(path.with_suffix(".json")), *words]:
        assert word in message, (word, message)


def test_sidecar_mount_other_than_the_reference_is_said_once(tmp_path, caplog):
    path = tmp_path / "curves.csv"
    write_measurement(path, measurement(5, {"mechanism": {"centre_of_gravity_mm": [0, 0, 0]}}))
    with caplog.at_level(logging.INFO, logger="flexcal"):
        mechanism = mechanism_from_metadata(read_measurement(path).metadata)
    assert mechanism.centre_of_gravity == (0.0, 0.0, 0.0)
    lines = [r.getMessage() for r in caplog.records if r.name.startswith("flexcal")]
    assert len(lines) == 1 and "centre of gravity (0, 0, 0) mm" in lines[0] and "(150, 0, 0) mm" in lines[0]
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="flexcal"):
        mechanism_from_metadata({"mechanism": {}})  # the reference mount: nothing to say
    assert not [r for r in caplog.records if r.name.startswith("flexcal")]


def test_measurement_larger_than_the_bound_is_refused_unread(tmp_path):
    path = tmp_path / "curves.csv"
    with path.open("wb") as handle:  # sparse: 1 GB that takes no disk
        handle.truncate(2**30)
    message = refusal(read_measurement, path)
    assert str(path) in message and "1,073,741,824 bytes" in message


def test_measurement_row_count_is_bounded(tmp_path, monkeypatch):
    import flexcal.validation.measurements as measurements

    monkeypatch.setattr(measurements, "MAX_POINTS", 10)
    path = tmp_path / "curves.csv"
    write_measurement(path, measurement(11, {}))
    assert "more than 10 data rows" in refusal(read_measurement, path)
    write_measurement(path, measurement(10, {}))
    assert read_measurement(path).n_points == 10


# --- trajectory files -------------------------------------------------------------------

@pytest.mark.parametrize("body, words", [
    # used to end in exit 1, "TypeError: float() argument must be ... not 'NoneType'"
    ("xa1_mm,xa2_mm,xa3_mm,leg\n0,0,0,1\n0.1,0\n", ["row 3 has 2 values, the header has 4"]),
    ("xa1_mm,xa2_mm,xa3_mm,leg\n0,0,0,1.7\n", ["row 2", "'leg'", "'1.7' must be an integer"]),  # was leg 1
    ("xa1_mm,xa2_mm,xa3_mm\n0,abc,0\n", ["row 2", "'xa2_mm'", "'abc' is not a number"]),
    ("xa1_mm,xa2_mm\n0,0\n", ["lacks column 'xa3_mm'"]),
    # used to be accepted: 250 mm is a unit mistake (m for mm x 1000), the measurement reader's limit
    ("xa1_mm,xa2_mm,xa3_mm\n0,0,0\n0,250,0\n", ["row 3", "'xa2_mm'", "250 mm exceeds the file limit of 100 mm"]),
], ids=["missing-cell", "fractional-leg", "not-a-number", "missing-column", "input-beyond-limit"])
def test_trajectory_rows_are_checked(tmp_path, body, words):
    path = tmp_path / "trajectory.csv"
    path.write_text(body)
    message = refusal(read_trajectory, path)
    for word in [str(path), *words]:
        assert word in message, (word, message)


def test_trajectory_of_a_scenario_names_both_files(tmp_path, capsys):
    (tmp_path / "t.csv").write_text("xa1_mm,xa2_mm,xa3_mm,leg\n0,0,0,1\n0.1,0\n")
    path = scenario_file(tmp_path, 'name = "x"\n[trajectory]\nkind = "file"\nfile = "t.csv"\n')
    status = cli.main(["truth", "--scenario", str(path), "--provider", "analytic", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert str(path) in err and "t.csv: row 3 has 2 values" in err


def test_design_trajectory_reads_as_before(tmp_path):
    path = tmp_path / "trajectory.csv"
    path.write_text("point,leg,xa1_mm,xa2_mm,xa3_mm\n1,1,0.100000000,0,-0.2\n2,2,0,0.5,0\n3,,1,1,1\n")
    inputs, leg = read_trajectory(path)
    np.testing.assert_array_equal(inputs, np.array([[0.1, 0, -0.2], [0, 0.5, 0], [1, 1, 1]]) * 1e-3)
    np.testing.assert_array_equal(leg, [1, 2, 1])  # a blank leg is leg 1, as before


# --- configuration files through the real command line ---------------------------------

@pytest.mark.parametrize("content, words", [
    (b"prior_scale = nan\n", ["prior_scale = NaN", "finite"]),  # used to be accepted
    (b"particles = 4\xe90\n", ["not UTF-8", "line 1"]),  # used to say "not a text file"
    (b"[particles]\nn = 3\n", ["particles = {\"n\": 3}", "must be an integer", "table"]),
    (b"swarm = 3\n", ["unknown key 'swarm' (= 3)", "particles"]),
], ids=["nan", "latin1", "table-for-int", "unknown-key"])
def test_bad_config_through_the_command_line(tmp_path, content, words):
    config = tmp_path / "verify.toml"
    config.write_bytes(content)
    result = subprocess.run([sys.executable, "-m", "flexcal.validation.cli", "verify", "--scenario", "table1",
                             "--config", str(config), "--print-config"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for word in [f"--config {config}", *words]:
        assert word in lines[0], (word, lines[0])


def test_sidecar_written_by_truth_reads_back(tmp_path):
    # every key flexcal truth writes is in the schema
    out = tmp_path / "t"
    path = scenario_file(tmp_path, 'name = "x"\nseed = 2\n[trajectory]\nn_points = 13\n'
                                   '[mechanism]\ncentre_of_gravity_mm = [0, 0, 0]\n'
                                   '[[effects]]\nname = "drift"\nrate = [5e-8, 5e-8, 1.5e-7]\n')
    assert cli.main(["truth", "--scenario", str(path), "--provider", "analytic", "--out", str(out), "-q"]) == 0
    metadata = read_measurement(out / "curves.csv").metadata
    assert metadata == json.loads((out / "curves.json").read_text())
    assert metadata["n_points"] == 13 and metadata["mount"]["payload"]["centre_of_gravity_mm"] == [0, 0, 0]
