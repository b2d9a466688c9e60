"""The options every command shares: help with examples, --config / --print-config,
--json, -q, and byte-identical reports for the same seed."""

import json
import re
import tomllib

import pytest

from flexcal.validation import cli
from flexcal.validation.cli.common import without_timings
from flexcal.validation.output import TIMING_KEYS
from flexcal.validation.config import check_default_config, merge_config

HEADER = "point,time_s,leg,xa1_mm,xa2_mm,xa3_mm,theta_x_urad,theta_y_urad,theta_z_urad"


@pytest.fixture
def small_csv(tmp_path):
    """Five postures of a plausible curve (the commands only need valid data)."""
    rows = [f"{k + 1},{k},0,{0.1 * k:.1f},{-0.05 * k:.2f},0.02,{1.0 + k},{-2.0 * k},{0.5 * k}" for k in range(5)]
    path = tmp_path / "curves.csv"
    path.write_text("\n".join([HEADER, *rows]) + "\n")
    return path


def test_merge_config_checks_keys_and_types():
    defaults = {"n": 3, "x": 0.5, "flag": False, "name": "a", "table": {"w": 0.9}, "grid": [1.0, 2.0]}
    merged = merge_config(defaults, {"x": 1, "table": {"w": 2}, "grid": [3, 4]}, source="f.toml")
    assert merged == {"n": 3, "x": 1.0, "flag": False, "name": "a", "table": {"w": 2.0}, "grid": [3.0, 4.0]}
    assert isinstance(merged["x"], float) and defaults["table"] == {"w": 0.9}  # defaults untouched
    for bad, words in [({"m": 1}, "unknown key 'm'"), ({"n": 1.5}, "n = 1.5 must be an integer"),
                       ({"flag": 0}, "boolean"), ({"table": 3}, "must be a table"),
                       ({"table": {"v": 1}}, "unknown key 'table.v'"), ({"grid": ["a"]}, r"grid\[0\] = \"a\" must be a number")]:
        with pytest.raises(ValueError, match=words):
            merge_config(defaults, bad, source="f.toml")


def test_default_config_must_be_toml():
    with pytest.raises(ValueError, match="TOML has no NoneType"):
        check_default_config({"seed": None})


def available_commands():
    return list(cli._available())


@pytest.mark.parametrize("command", available_commands())
def test_every_help_has_examples_and_common_options(command, capsys):
    assert cli.main([command, "--help"]) == 0
    out = capsys.readouterr().out
    assert f"usage: flexcal {command}" in out
    assert "examples:" in out and f"flexcal {command} " in out.split("examples:")[1]
    assert "--quiet" in out and "--debug" in out


def test_top_level_help_lists_every_available_command(capsys):
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    for command in available_commands():
        assert re.search(rf"^ +{re.escape(command)}(\s|$)", out, flags=re.MULTILINE), command


def test_print_config_round_trips_and_precedence(tmp_path, capsys):
    from flexcal.validation.cli.verify import DEFAULT_CONFIG

    assert cli.main(["verify", "--print-config"]) == 0  # no required option needed
    assert tomllib.loads(capsys.readouterr().out) == DEFAULT_CONFIG
    config = tmp_path / "v.toml"
    config.write_text("particles = 60\niterations = 40\npolish = false\n")
    assert cli.main(["verify", "--config", str(config), "--iterations", "7", "--print-config"]) == 0
    effective = tomllib.loads(capsys.readouterr().out)
    # command line (iterations) > file (particles, polish) > defaults (sobol_n)
    assert effective == {**DEFAULT_CONFIG, "particles": 60, "iterations": 7, "polish": False}


def test_config_file_sets_option_defaults(tmp_path, small_csv, capsys):
    config = tmp_path / "s.toml"
    config.write_text("sobol_n = 8\ncalibration_seed = 5\n")
    out = tmp_path / "out"
    assert cli.main(["sensitivity", "--data", str(small_csv), "--model", "second-order",
                     "--config", str(config), "--out", str(out), "-q"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["summary"]["n_base"] == 8 and report["summary"]["seed"] == 5
    assert report["config"]["sobol_n"] == 8 and report["config"]["provider"] == "fem"


def test_json_prints_only_the_summary(tmp_path, small_csv, capsys):
    out = tmp_path / "out"
    assert cli.main(["sensitivity", "--data", str(small_csv), "--model", "second-order",
                     "--sobol-n", "4", "--out", str(out), "--json"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1
    summary = json.loads(lines[0])
    assert summary["n_base"] == 4 and summary["out"] == str(out)
    assert summary["files"] == ["report.json", "report.md", "sensitivity.png"]


def test_quiet_prints_nothing_on_stdout(tmp_path, capsys):
    assert cli.main(["forward", "--inputs-mm", "0.1,0,0", "-q"]) == 0
    assert capsys.readouterr().out == ""


def test_without_timings_removes_only_timing_keys():
    report = {"wall_s": 3.0, "fit": 1.0, "pso": {"timings_s": {"a": 1}, "n": 2}, "rows": [{"elapsed_s": 1, "x": 0}]}
    assert without_timings(report) == {"fit": 1.0, "pso": {"n": 2}, "rows": [{"x": 0}]}
    assert TIMING_KEYS == {"wall_s", "timings_s", "elapsed_s"}


def test_split_timings_keeps_the_nesting():
    from flexcal.validation.output import split_timings

    report = {"wall_s": 3.0, "fit": 1.0, "pso": {"timings_s": {"a": 1}, "n": 2},
              "rows": [{"elapsed_s": 1, "x": 0}, {"x": 1}], "names": ["a", "b"]}
    results, timings = split_timings(report)
    assert results == {"fit": 1.0, "pso": {"n": 2}, "rows": [{"x": 0}, {"x": 1}], "names": ["a", "b"]}
    # rows[k]'s time is timings["rows"][k]; branches without a time are left out
    assert timings == {"wall_s": 3.0, "pso": {"timings_s": {"a": 1}}, "rows": [{"elapsed_s": 1}, {}]}
    assert split_timings({"fit": 1.0}) == ({"fit": 1.0}, None)


def test_json_summary_takes_the_times_from_timings_json(tmp_path):
    from flexcal.validation.cli.common import summary_of
    from flexcal.validation.output import write_report

    write_report(tmp_path, {"n": 3, "wall_s": 1.5, "rows": [{"wall_s": 0.5}]})
    assert json.loads((tmp_path / "report.json").read_text()) == {"n": 3, "rows": [{}]}
    assert summary_of(tmp_path) == {"n": 3, "wall_s": 1.5, "out": str(tmp_path),
                                    "files": ["report.json", "timings.json"]}
    (tmp_path / "timings.json").unlink()
    write_report(tmp_path, {"summary": {"n": 3, "wall_s": 2.0}, "x": 1})
    assert summary_of(tmp_path)["wall_s"] == 2.0


def run_twice(tmp_path, argv, names):
    """The files ``names`` of two runs of ``argv`` (with --out appended)."""
    runs = []
    for k in range(2):
        out = tmp_path / f"run{k}"
        assert cli.main([*argv, "--out", str(out), "-q"]) == 0
        runs.append({n: (out / n).read_bytes() for n in names})
    return runs


def test_same_seed_same_report_identify(tmp_path, small_csv):
    first, second = run_twice(tmp_path, ["identify", "--data", str(small_csv), "--model", "second-order",
                                         "--sources", "D1.x0,D1.CL,D1.mu",
                                         "--particles", "40", "--iterations", "5", "--calibration-seed", "3"],
                              ["report.json", "report.md", "timings.json"])
    # the wall-clock times are in timings.json only: report.json and report.md repeat to the byte
    assert first["report.json"] == second["report.json"] and first["report.md"] == second["report.md"]
    report, timings = (json.loads(first[name]) for name in ("report.json", "timings.json"))
    assert without_timings(report) == report and timings["wall_s"] > 0


def test_same_seed_same_report_sensitivity_and_forward(tmp_path, small_csv):
    first, second = run_twice(tmp_path, ["sensitivity", "--data", str(small_csv), "--model", "second-order",
                                         "--sobol-n", "8"],
                              ["report.json", "report.md"])
    assert first == second  # no timings in this report: byte-identical as a whole
    first, second = run_twice(tmp_path / "fw", ["forward", "--inputs-mm", "0.3,0.1,0"], ["report.json", "report.md"])
    assert first == second
    assert (tmp_path / "fw" / "run0" / "point.png").is_file()  # every --out holds a picture


def test_same_seed_same_truth_curves(tmp_path):
    # the brief's example: the analytic virtual prototype with noise, same seed -> same bytes
    first, second = run_twice(tmp_path, ["truth", "--scenario", "table1", "--provider", "analytic", "--seed", "4",
                                         "--noise-urad", "0.3"], ["curves.csv", "curves.json"])
    assert first == second


def test_same_seed_same_diagnosis_and_compensation(tmp_path):
    # a noisy analytic-prototype curve, then the two long jobs twice each: their reports
    # must agree to the byte (the wall-clock times are in timings.json)
    assert cli.main(["truth", "--scenario", "table1", "--provider", "analytic", "--noise-urad", "0.5",
                     "--out", str(tmp_path / "t"), "-q"]) == 0
    curves = str(tmp_path / "t" / "curves.csv")
    for argv, name in ((["diagnose", curves, "--model-stiffness", "closed-form"], "diag"),
                       (["compensate", "--data", curves, "--particles", "60", "--iterations", "10",
                         "--sobol-n", "32", "--max-rounds", "2"], "comp")):
        first, second = run_twice(tmp_path / name, argv, ["report.json", "report.md"])
        assert first == second
