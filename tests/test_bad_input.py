"""Bad input anywhere: one line on stderr naming the problem, exit status 2, no
traceback, no output folder (issue #8). ``--debug`` shows the traceback."""

import subprocess
import sys

import numpy as np
import pytest

from flexcal.validation import cli

HEADER = "point,time_s,leg,xa1_mm,xa2_mm,xa3_mm,theta_x_urad,theta_y_urad,theta_z_urad"
GOOD_ROWS = ["1,0,0,0.1,0,0,1.0,2.0,3.0", "2,1,0,0.2,0,0,1.5,2.5,3.5", "3,2,0,0.3,0,0,2.0,3.0,4.0"]


def write_csv(path, rows, header=HEADER):
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def assert_one_line_error(capsys, status, words, out=None, code=2):
    captured = capsys.readouterr()
    assert status == code, captured.err
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err  # one line, so no traceback
    assert "Traceback" not in captured.err
    for word in words:
        assert word in lines[0], (word, lines[0])
    if out is not None:
        assert not out.exists()
    return lines[0]


def sensitivity(data, out, *extra):
    return cli.main(["sensitivity", "--data", str(data), "--sobol-n", "4", "--out", str(out), *extra])


@pytest.mark.parametrize("rows, header, words", [
    (["1,0,0,0.1,0,0,abc,2.0,3.0"], HEADER, ["row 2", "theta_x_urad", "'abc' is not a number"]),
    (["1,0,0,0.1,0,0,1.0,2.0"], HEADER.rsplit(",", 1)[0], ["header", "theta_z_urad"]),
    (["1,0,0,0.1,0,0,nan,2.0,3.0"], HEADER, ["row 2", "theta_x_urad", "not finite"]),
    # an input of 250 mm is a stroke in m typed as mm (or worse): the plausibility check
    ([*GOOD_ROWS[:1], "2,1,0,250,0,0,1.0,2.0,3.0"], HEADER, ["row 3", "xa1_mm", "mm exceeds"]),
    ([], HEADER, ["no data rows"]),
], ids=["bad-number", "missing-column", "nan", "wrong-units", "empty"])
def test_malformed_measurement_csv(tmp_path, capsys, rows, header, words):
    data = write_csv(tmp_path / "curves.csv", rows, header)
    out = tmp_path / "out"
    assert_one_line_error(capsys, sensitivity(data, out), [str(data), *words], out)


def test_missing_csv(tmp_path, capsys):
    out = tmp_path / "out"
    status = cli.main(["identify", "--data", str(tmp_path / "nope.csv"), "--out", str(out)])
    assert_one_line_error(capsys, status, ["flexcal identify: error", "nope.csv", "does not exist"], out)


def test_out_of_range_parameter(tmp_path, capsys):
    params = tmp_path / "errors.toml"
    params.write_text('"D1.CL" = 5.0\n')  # clearance range is a fraction of a mm (docs/parameters.md)
    out = tmp_path / "out"
    status = cli.main(["forward", "--inputs-mm", "0.1,0,0", "--params", str(params), "--out", str(out)])
    assert_one_line_error(capsys, status, ["D1.CL"], out)


@pytest.mark.parametrize("args, words", [
    (["--type", "circular", "--radius-mm", "5", "--thickness-mm", "0", "--width-mm", "10"], ["thickness=0"]),
    # fillets larger than half the leaf: the notch does not fit in the segment
    (["--type", "leaf", "--length-mm", "20", "--thickness-mm", "4", "--width-mm", "40", "--fillet-mm", "12"],
     ["fillet=12"]),
    (["--type", "circular", "--radius-mm", "5", "--thickness-mm", "1", "--width-mm", "10", "--block-mm", "0"],
     ["block_length=0"]),
    (["--type", "circular", "--radius-mm", "5", "--thickness-mm", "1", "--width-mm", "10", "--elements-through",
      "0"], ["--elements-through=0"]),
], ids=["zero-thickness", "fillet-too-big", "no-block", "no-elements"])
def test_impossible_geometry(tmp_path, capsys, args, words):
    out = tmp_path / "out"
    assert_one_line_error(capsys, cli.main(["hinge", *args, "--out", str(out)]), ["flexcal hinge: error", *words], out)


@pytest.mark.parametrize("text, words", [
    ("particles = 40\nswarm_size = 3\n", ["unknown key 'swarm_size'", "particles"]),
    ("particles = \"many\"\n", ["particles", "must be an integer"]),
    ("polish = 1\n", ["polish", "boolean"]),
    ("provider = \"abaqus\"\n", ["provider", "one of", "analytic"]),
    ("particles = = 3\n", ["not valid TOML"]),
], ids=["unknown-key", "wrong-type", "int-for-bool", "bad-choice", "syntax"])
def test_bad_config_file(tmp_path, capsys, text, words):
    config = tmp_path / "verify.toml"
    config.write_text(text)
    out = tmp_path / "out"
    status = cli.main(["verify", "--scenario", "table1", "--config", str(config), "--out", str(out)])
    assert_one_line_error(capsys, status, ["flexcal verify: error", *words], out)


def test_missing_config_file(tmp_path, capsys):
    status = cli.main(["verify", "--scenario", "table1", "--config", str(tmp_path / "no.toml"), "--out", "x"])
    assert_one_line_error(capsys, status, ["--config", "no.toml", "no such file"])


def test_solver_that_does_not_converge(tmp_path, capsys):
    # 50 mrad about x and y is far outside the mount's workspace (~ +-5 mrad): the
    # small-deflection inverse diverges and must say so, not print a traceback
    out = tmp_path / "out"
    status = cli.main(["inverse", "--target-urad", "50000,50000,0", "--out", str(out)])
    assert_one_line_error(capsys, status, ["did not converge", "too large"], out)


def test_unknown_scenario(tmp_path, capsys):
    out = tmp_path / "out"
    status = cli.main(["truth", "--scenario", "tabel1", "--provider", "analytic", "--out", str(out)])
    assert_one_line_error(capsys, status, ["tabel1", "built-in"], out)


@pytest.mark.parametrize("argv, words", [
    (["hinge", "--type", "circular"], ["required", "--thickness-mm", "--help"]),
    (["hinge", "--type", "square"], ["invalid choice", "square"]),
    (["verify", "--scenario", "table1", "--particles", "many", "--out", "x"], ["--particles", "'many'"]),
    (["frobnicate"], ["unknown command", "frobnicate"]),
], ids=["missing-option", "bad-choice", "bad-int", "unknown-command"])
def test_usage_errors_are_one_line(capsys, argv, words):
    assert_one_line_error(capsys, cli.main(argv), words)


def test_debug_shows_the_traceback(tmp_path, capsys):
    status = cli.main(["hinge", "--type", "circular", "--radius-mm", "5", "--thickness-mm", "0", "--width-mm", "10",
                       "--out", str(tmp_path / "out"), "--debug"])
    err = capsys.readouterr().err
    assert status == 2
    assert "Traceback" in err and err.strip().splitlines()[-1].startswith("flexcal hinge: error:")


def test_ctrl_c_exits_130_and_writes_nothing(tmp_path, capsys, monkeypatch):
    from flexcal.validation.cli import forward as cmd_forward

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cmd_forward, "print_point", interrupted)  # raised inside staged_output
    out = tmp_path / "out"
    status = cli.main(["forward", "--inputs-mm", "0.1,0,0", "--out", str(out)])
    assert_one_line_error(capsys, status, ["interrupted"], out, code=130)
    assert list(tmp_path.iterdir()) == []  # no staging folder left behind either


def test_a_bug_is_one_line_with_status_1(tmp_path, capsys, monkeypatch):
    from flexcal.validation.cli import forward as cmd_forward

    def broken(*args, **kwargs):
        raise TypeError("unsupported operand")

    monkeypatch.setattr(cmd_forward, "point_report", broken)
    status = cli.main(["forward", "--inputs-mm", "0.1,0,0"])
    assert_one_line_error(capsys, status, ["internal error", "TypeError", "--debug"], code=1)


def test_console_script_status_and_stderr(tmp_path):
    """The installed entry point: status 2 and one stderr line from a real process."""
    result = subprocess.run([sys.executable, "-m", "flexcal.validation.cli", "hinge", "--type", "leaf",
                             "--length-mm", "20", "--thickness-mm", "4", "--width-mm", "40", "--fillet-mm", "12",
                             "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1 and "fillet=12" in result.stderr
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------------------
# issue 14: sizes no hinge has, negative comma lists, a byte-order mark

HINGE = ["hinge", "--type", "circular", "--radius-mm", "5", "--thickness-mm", "1", "--width-mm", "10"]


@pytest.mark.parametrize("change, words", [
    (["--radius-mm", "1e300"], ["--radius-mm=1e+300 mm", "out of range", "10000 mm"]),
    (["--radius-mm", "inf"], ["--radius-mm=inf", "finite"]),
    (["--width-mm", "1e-6"], ["--width-mm=1e-06 mm", "0.01"]),
    (["--elements-through", "1e6"], ["--elements-through=1e+06", "1 to 16"]),
    (["--elements-through", "0.5"], ["--elements-through=0.5", "1 to 16"]),
], ids=["radius-1e300", "radius-inf", "width-1nm", "elements-1e6", "elements-half"])
def test_hinge_sizes_no_hinge_has(tmp_path, capsys, change, words):
    # used to end in "internal error: Standard_DomainError" (exit 1) from inside OCCT
    out = tmp_path / "out"
    argv = HINGE + change + ["--out", str(out)]
    assert_one_line_error(capsys, cli.main(argv), ["flexcal hinge: error", *words], out)


def test_chain_sizes_no_chain_has(tmp_path, capsys):
    out = tmp_path / "out"
    status = cli.main(["chain", "--reference", "D1", "--section-mm", "1e300", "--out", str(out)])
    assert_one_line_error(capsys, status, ["flexcal chain: error", "--section-mm=1e+300 mm"], out)


@pytest.mark.parametrize("argv, expected", [
    (["inverse", "--target-urad", "-100,200,50", "--json"], "theta_urad"),
    (["forward", "--inputs-mm", "-0.5,0,0", "--json"], "theta_urad"),
    (["forward", "--inputs-mm", "-5e-1, -0.1,0", "--json"], "theta_urad"),
], ids=["inverse", "forward", "forward-exponent-spaces"])
def test_comma_lists_may_start_with_a_minus(capsys, argv, expected):
    # argparse took '-100,200,50' for an option ("expected one argument"); no '=' needed now
    assert cli.main(argv) == 0, capsys.readouterr().err
    assert expected in capsys.readouterr().out


def test_comma_list_starting_with_minus_equals_the_form_with_equals(capsys):
    assert cli.main(["inverse", "--target-urad", "-100,200,50", "--json"]) == 0
    spaced = capsys.readouterr().out
    assert cli.main(["inverse", "--target-urad=-100,200,50", "--json"]) == 0
    assert capsys.readouterr().out == spaced


def test_an_unknown_option_is_still_an_option(capsys):
    # only numbers are taken as values: '-x' stays an (unknown) option
    assert_one_line_error(capsys, cli.main(["forward", "--inputs-mm", "-x"]), ["--inputs-mm", "expected one argument"])


def test_csv_with_a_byte_order_mark_reads(tmp_path):
    from flexcal.validation.measurements import read_measurement

    plain = write_csv(tmp_path / "plain.csv", GOOD_ROWS)
    marked = tmp_path / "marked.csv"
    marked.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())  # "CSV UTF-8" of spreadsheet programs
    a, b = read_measurement(plain), read_measurement(marked)
    np.testing.assert_array_equal(a.angles, b.angles)
    np.testing.assert_array_equal(a.point, b.point)


@pytest.mark.parametrize("content, words", [
    (b"point,time_s\xff\xfe\n", ["not UTF-8", "byte 12"]),
    (HEADER.encode() + b"\n1,0,0,0.1,0,0,1\x00,2,3\n", ["NUL bytes"]),
    (HEADER.encode() + b'\n1,0,0,0.1,0,0,"1"x,2,3\n', ["row 2"]),
    (HEADER.encode() + b"\n1e300,0,0,0.1,0,0,1,2,3\n", ["row 2", "'point'", "too large"]),
], ids=["latin1-bytes", "nul", "quote", "huge-index"])
def test_unreadable_csv_is_one_line(tmp_path, capsys, content, words):
    data = tmp_path / "curves.csv"
    data.write_bytes(content)
    out = tmp_path / "out"
    assert_one_line_error(capsys, sensitivity(data, out), [str(data), *words], out)


def test_diagnose_refuses_a_short_file_before_any_fem(tmp_path, capsys, monkeypatch):
    # the 2-point file used to build the model's FEM correction (~30 s cold) first
    import flexcal.validation.runs.model_correction as correction

    def no_fem(*args, **kwargs):
        raise AssertionError("the FEM correction was built before the file was checked")

    monkeypatch.setattr(correction, "model_space", no_fem)
    data = write_csv(tmp_path / "curves.csv", GOOD_ROWS)
    out = tmp_path / "out"
    status = cli.main(["diagnose", str(data), "--out", str(out)])
    assert_one_line_error(capsys, status, ["flexcal diagnose: error", "3 points", "at least 20"], out)
