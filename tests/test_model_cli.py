"""flexcal forward / inverse on the command line."""

import json

import numpy as np
import pytest

from flexcal.validation import cli


def run_json(capsys, argv):
    assert cli.main(argv) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1  # exactly one JSON object
    return json.loads(out[0])


def test_forward_json_has_the_agreed_keys(capsys):
    report = run_json(capsys, ["forward", "--inputs-mm", "0.5,0,0.1", "--json"])
    for key in ("theta_urad", "inputs_mm", "point_class", "chain_states"):
        assert key in report
    assert report["inputs_mm"] == [0.5, 0.0, 0.1]
    assert report["point_class"] in ("S1", "S2", "S3")
    assert set(report["chain_states"]) == {"D1", "D2", "D3"}


def test_inverse_returns_the_forward_inputs(capsys, tmp_path):
    params = tmp_path / "p.toml"
    params.write_text('"D1.CL" = 0.2\n"D1.mu" = 0.85\n"D2.x0" = 0.1\n')
    fwd = run_json(capsys, ["forward", "--inputs-mm=-0.4,0.2,0.1", "--directions=-1,1,1", "--params", str(params),
                            "--json"])
    target = ",".join(repr(v) for v in fwd["theta_urad"])
    inv = run_json(capsys, ["inverse", f"--target-urad={target}", "--directions=-1,1,1", "--params", str(params),
                            "--json"])
    np.testing.assert_allclose(inv["inputs_mm"], [-0.4, 0.2, 0.1], atol=1e-6)  # 1 nm; JSON keeps 17 digits
    assert inv["chain_states"] == fwd["chain_states"]


def test_human_output_names_states_and_class(capsys):
    assert cli.main(["forward", "--inputs-mm", "0,0,0"]) == 0
    out = capsys.readouterr().out
    assert "point class: S" in out and "D3" in out and "theta_x" in out


@pytest.mark.parametrize("argv, words", [
    (["forward", "--inputs-mm", "1,2"], ["--inputs-mm", "three"]),
    (["forward", "--inputs-mm", "0,0,0", "--directions", "1,0,1"], ["--directions", "+1 or -1"]),
    (["inverse", "--target-urad", "a,b,c"], ["--target-urad"]),
])
def test_bad_input_is_one_line_and_status_2(capsys, argv, words):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    for word in words:
        assert word in err[0]


def test_unknown_and_out_of_range_parameters(capsys, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"D1.CL": 0.9, "Q1.w": 3}')
    assert cli.main(["forward", "--inputs-mm", "0,0,0", "--params", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "Q1.w" in err or "D1.CL" in err
