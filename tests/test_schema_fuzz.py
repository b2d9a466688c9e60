"""Fuzz every typed-file loader (issue 23): random TOML/JSON values of random types at
random keys of a valid scenario, sidecar and configuration, and random cells of a
trajectory CSV. Every outcome is a load or a one-line ValueError naming the file (never
TypeError, KeyError, AttributeError, ...); the command line answers 0 or 2, never 1."""

import json
import math

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from flexcal.validation import cli
from flexcal.validation.measurements import Measurement, read_measurement, write_measurement
from flexcal.validation.prototype.scenario import load_scenario, mechanism_from_metadata, read_trajectory

FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

_TEXT = st.text(max_size=6)
_TOML_SCALARS = st.one_of(st.booleans(), st.integers(min_value=-2**63, max_value=2**63 - 1),
                          st.integers(min_value=-3, max_value=20), st.floats(), _TEXT)
TOML_VALUES = st.recursive(_TOML_SCALARS, lambda inner: st.lists(inner, max_size=4)
                           | st.dictionaries(_TEXT, inner, max_size=3), max_leaves=8)
JSON_VALUES = st.recursive(_TOML_SCALARS | st.none(), lambda inner: st.lists(inner, max_size=4)
                           | st.dictionaries(_TEXT, inner, max_size=3), max_leaves=8)


def _edit(document: dict, path: tuple, value, delete: bool) -> dict:
    """``document`` with ``value`` at the key path (or the key removed); a parent that is
    not a table becomes one."""
    document = json.loads(json.dumps(document))
    node = document
    for key in path[:-1]:
        if isinstance(node, list):  # an array of tables: edit its first table
            if not node or not isinstance(node[0], dict):
                node[:] = [{}]
            node = node[0]
            continue
        key = str(key)
        if not isinstance(node.get(key), (dict, list)):
            node[key] = {}
        node = node[key]
    if isinstance(node, list):
        if not node or not isinstance(node[0], dict):
            node[:] = [{}]
        node = node[0]
    if delete:
        node.pop(str(path[-1]), None)
    else:
        node[str(path[-1])] = value
    return document


def _edits(paths, values):
    known = st.sampled_from(paths)
    anywhere = st.tuples(_TEXT) | st.tuples(st.sampled_from([p[0] for p in paths]), _TEXT)
    return st.lists(st.tuples(known | anywhere, values, st.booleans()), min_size=1, max_size=3)


def _refused_with_file(call, path, *args):
    """call(path, ...) or None if it raised a one-line ValueError naming ``path``."""
    try:
        return call(str(path), *args)
    except ValueError as error:
        assert str(path) in str(error), error
        assert "\n" not in str(error), error
        return None


# --- scenario ---------------------------------------------------------------------------

SCENARIO = {"name": "fuzz", "seed": 3, "draw_unset": True, "errors": {"D1.CL": 0.2},
            "sensors": {"noise_urad": 0.5, "offset_urad": [0.0, 0.0, 0.0]}, "transmission": {"breakaway_force_n": 2.0},
            "mechanism": {"payload_mass_kg": 300}, "trajectory": {"kind": "standard", "n_points": 13, "dwell_s": 2.0},
            "effects": [{"name": "drift", "rate": [5e-8, 5e-8, 1.5e-7]}]}
SCENARIO_PATHS = [("name",), ("seed",), ("draw_unset",), ("errors",), ("errors", "D1.CL"), ("errors", "D2.mu"),
                  ("sensors",), ("sensors", "noise_urad"), ("sensors", "offset_urad"), ("transmission",),
                  ("transmission", "breakaway_force_n"), ("mechanism",), ("mechanism", "centre_of_gravity_mm"),
                  ("mechanism", "payload_mass_kg"), ("trajectory",), ("trajectory", "kind"),
                  ("trajectory", "n_points"), ("trajectory", "dwell_s"), ("trajectory", "file"), ("effects",),
                  ("effects", 0, "name"), ("effects", 0, "rate"), ("effects", 0, "magnitude_urad"),
                  ("effects", 0, "seed")]


def test_the_unedited_scenario_loads(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps(SCENARIO))
    assert load_scenario(str(path)).inputs.shape == (13, 3)


@FUZZ
@given(edits=_edits(SCENARIO_PATHS, TOML_VALUES))
def test_scenario_fuzz(tmp_path, edits):
    document = SCENARIO
    for path, value, delete in edits:
        document = _edit(document, path, value, delete)
    trajectory = document.get("trajectory")
    n_points = trajectory.get("n_points") if isinstance(trajectory, dict) else None
    if type(n_points) is int and 1000 < n_points <= 100_000:
        trajectory["n_points"] = 13  # a valid long trajectory only costs time
    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps(document), encoding="utf-8")
    scenario = _refused_with_file(load_scenario, path)
    event("loaded" if scenario is not None else "refused")
    if scenario is not None:
        assert np.all(np.isfinite(scenario.values)) and np.all(np.isfinite(scenario.noise))
        assert scenario.dwell > 0 and isinstance(scenario.seed, int)


# --- measurement sidecar ----------------------------------------------------------------

N_ROWS = 5
SIDECAR = {"generator": "fuzz", "provider": "analytic", "scenario": "x", "seed": 1,
           "preset_errors": [{"name": "D1.CL", "unit": "mm", "value": 0.2, "explicit": True}],
           "sensors": {"noise_urad": [0.0, 0.0, 0.0], "offset_urad": [0.0, 0.0, 0.0]},
           "transmission": {"breakaway_force_n": 2.0}, "effects": [], "n_points": N_ROWS,
           "mechanism": {"centre_of_gravity_mm": [150, 0, 0]}, "injected_effects": [],
           "prototype": {"max_force_residual_n": 1e-6, "max_moment_residual_nm": 1e-6, "newton_iterations_total": 9,
                         "point_class": ["S1"] * N_ROWS}, "notes": {"operator": "me"}}
SIDECAR_PATHS = [(k,) for k in SIDECAR] + [("preset_errors", 0, "value"), ("preset_errors", 0, "name"),
                                          ("sensors", "noise_urad"), ("transmission", "breakaway_force_n"),
                                          ("mechanism", "centre_of_gravity_mm"), ("mechanism", "payload_mass_kg"),
                                          ("prototype", "point_class"), ("prototype", "newton_iterations_total")]


@pytest.fixture(scope="module")
def curve(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sidecar")
    k = np.arange(N_ROWS)
    write_measurement(folder / "curves.csv", Measurement(
        point=k + 1, time=k * 2.0, leg=np.ones(N_ROWS, int), inputs=np.full((N_ROWS, 3), 1e-4),
        angles=np.full((N_ROWS, 3), 1e-6), extras={}, metadata={}))
    return folder / "curves.csv"


def test_the_unedited_sidecar_loads(curve):
    curve.with_suffix(".json").write_text(json.dumps(SIDECAR))
    assert read_measurement(curve).metadata == SIDECAR


@FUZZ
@given(edits=_edits(SIDECAR_PATHS, JSON_VALUES))
def test_sidecar_fuzz(curve, edits):
    document = SIDECAR
    for path, value, delete in edits:
        document = _edit(document, path, value, delete)
    side = curve.with_suffix(".json")
    side.write_text(json.dumps(document), encoding="utf-8")
    try:
        measurement = read_measurement(curve)
    except ValueError as error:
        assert str(side) in str(error) and "\n" not in str(error), error
        event("refused")
        return
    event("loaded")
    mechanism_from_metadata(measurement.metadata)  # what the commands do with a loaded sidecar


# --- trajectory CSV ---------------------------------------------------------------------

_CELLS = st.sampled_from(["0", "0.1", "-2.5", "1e-3", "1", "2", "", " ", "nan", "inf", "abc", "1.7", "-1", '"', "1e400",
                          "\x00", "é", "0x10"])
_HEADERS = st.sampled_from(["xa1_mm", "xa2_mm", "xa3_mm", "leg", "point", "other", ""])


@FUZZ
@given(header=st.lists(_HEADERS, min_size=1, max_size=6),
       rows=st.lists(st.lists(_CELLS, min_size=0, max_size=7), max_size=6))
def test_trajectory_fuzz(tmp_path, header, rows):
    path = tmp_path / "trajectory.csv"
    path.write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n", encoding="utf-8")
    result = _refused_with_file(read_trajectory, path)
    event("loaded" if result is not None else "refused")
    if result is not None:
        inputs, leg = result
        assert inputs.ndim == 2 and inputs.shape[1] == 3 and leg.shape == (len(inputs),)
        assert np.all(np.isfinite(inputs)) and np.all(leg >= 0)


# --- configuration through the command line ---------------------------------------------

CONFIG_PATHS = [("provider",), ("sobol_n",), ("sobol_threshold",), ("particles",), ("iterations",), ("polish",),
                ("remove_offset",), ("calibration_seed",), ("method",), ("prior_scale",), ("model_stiffness",),
                ("second_order",)]


@FUZZ
@given(edits=_edits(CONFIG_PATHS, TOML_VALUES))
def test_config_fuzz_through_the_command_line(tmp_path, capsys, edits):
    document = {}
    for path, value, delete in edits:
        document = _edit(document, path, value, delete)
    config = tmp_path / "verify.toml"
    config.write_text(tomli_w.dumps(document), encoding="utf-8")
    status = cli.main(["verify", "--scenario", "table1", "--config", str(config), "--print-config"])
    captured = capsys.readouterr()
    assert status in (0, 2), captured.err
    event(f"status {status}" + (f": {captured.err.split(': ')[-1][:25]}" if status == 2 else ""))
    if status == 2:
        assert captured.err.count("\n") == 1 and str(config) in captured.err, captured.err
    else:
        printed = captured.out
        for key, value in document.items():  # what was accepted is what is printed
            if isinstance(value, float) and math.isfinite(value):
                assert f"{key} = " in printed
