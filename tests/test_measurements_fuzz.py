"""Fuzz the measurement reader (issue 14): random bytes and random edits of a good CSV give
either a correct read or a ``ValueError`` naming the file, never another exception."""

import csv
import io
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flexcal.validation import cli
from flexcal.validation.measurements import REQUIRED_COLUMNS, read_measurement

HEADER = ",".join(REQUIRED_COLUMNS)
GOOD = [HEADER] + [f"{k},{k}.0,0,{0.01 * k:.2f},0,-0.1,{k}.5,-2.0,3.0" for k in range(1, 6)]
FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _read_or_value_error(path):
    """The reader's result, or None when it refused the file with a ValueError naming it."""
    try:
        return read_measurement(path)
    except ValueError as error:
        assert str(path) in str(error), error  # every refusal names the file
        assert "\n" not in str(error)  # one line
        return None


def _expected(text: str):
    """What a correct read must hold: the numeric cells of the rows, or None if some
    cell is not a finite number (the reader must then refuse)."""
    rows = [r for r in csv.reader(io.StringIO(text.removeprefix("\ufeff")))]
    header = [h.strip() for h in rows[0]]
    data = [r for r in rows[1:] if r and any(c.strip() for c in r)]
    table = []
    for row in data:
        try:
            values = [float(c) for c in row]
        except ValueError:
            return None
        if not all(math.isfinite(v) for v in values):
            return None
        table.append(dict(zip(header, values)))
    return table


@FUZZ
@given(content=st.binary(max_size=400))
def test_random_bytes(tmp_path, content):
    path = tmp_path / "curves.csv"
    path.write_bytes(content)
    _read_or_value_error(path)


_EDITS = st.sampled_from(["delete", "insert", "replace", "duplicate_line", "drop_line", "bom", "crlf"])
_SNIPPETS = st.sampled_from(["", ",", "\n", '"', "nan", "inf", "-", "1e400", "1e300", "0x10", " ", "\x00", "é",
                             "\ufeff", "point", "-0", "1_000", "١"])


@FUZZ
@given(edits=st.lists(st.tuples(_EDITS, st.integers(min_value=0, max_value=10_000), _SNIPPETS), max_size=4))
def test_random_edits_of_a_good_file(tmp_path, edits):
    text = "\n".join(GOOD) + "\n"
    for kind, where, snippet in edits:
        at = where % (len(text) + 1)
        lines = text.split("\n")
        line = where % len(lines)
        if kind == "delete":
            text = text[:at] + text[at + 1:]
        elif kind == "insert":
            text = text[:at] + snippet + text[at:]
        elif kind == "replace":
            text = text[:at] + snippet + text[at + 1:]
        elif kind == "duplicate_line":
            text = "\n".join(lines[:line + 1] + lines[line:])
        elif kind == "drop_line":
            text = "\n".join(lines[:line] + lines[line + 1:])
        elif kind == "bom":
            text = "\ufeff" + text
        else:
            text = text.replace("\n", "\r\n")
    path = tmp_path / "curves.csv"
    path.write_text(text, encoding="utf-8", newline="")
    measurement = _read_or_value_error(path)
    if measurement is None:
        return
    # a file that was read must have been read correctly: every row, in the right units
    expected = _expected(text)
    assert expected is not None, "a file with a non-number cell was accepted"
    assert measurement.n_points == len(expected)
    got = np.column_stack([measurement.inputs * 1e3, measurement.angles * 1e6])
    want = np.array([[row[c] for c in REQUIRED_COLUMNS[3:]] for row in expected])
    # rtol: the reader scales mm -> m and urad -> rad, the check back: two roundings of
    # 1.1e-16 each; nothing else may change a value
    np.testing.assert_allclose(got, want, rtol=4e-16, atol=0)
    np.testing.assert_array_equal(measurement.point, [int(row["point"]) for row in expected])


def test_the_unedited_file_reads(tmp_path):
    path = tmp_path / "curves.csv"
    path.write_text("\n".join(GOOD) + "\n")
    assert read_measurement(path).n_points == len(GOOD) - 1


def test_fuzzed_failure_through_the_command_line_is_exit_2(tmp_path, capsys):
    path = tmp_path / "curves.csv"
    path.write_bytes(b"\xef\xbb\xbf" + HEADER.encode() + b"\n1,0,0,\x00,0,0,1,2,3\n")
    status = cli.main(["identify", "--data", str(path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "Traceback" not in err
