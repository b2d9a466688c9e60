"""The one rule on Sobol's base sample N (``calibration.sensitivity.check_n_base``): every
command that takes it refuses 500 (the paper's N, not a power of two) with the same one-line
error and exit status 2, before any computation and before writing its --out folder."""

from __future__ import annotations

import pytest

from flexcal.validation import cli

REFUSAL = "must be a power of two (e.g. 512): the Sobol sequence loses its balance otherwise"
SCENARIO = ["--scenario", "table1", "--provider", "analytic", "--model", "second-order",
            "--model-stiffness", "closed-form"]


@pytest.mark.parametrize("command, args", [
    ("verify", SCENARIO),
    ("sensitivity", SCENARIO),
    # refused before its data file is read (the file does not exist)
    ("compensate", ["--data", "no-such-curves.csv", "--model-stiffness", "closed-form"]),
])
def test_sobol_n_500_is_refused_in_one_line(command, args, tmp_path, capsys):
    out = tmp_path / "run"
    assert cli.main([command, *args, "--sobol-n", "500", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert f"--sobol-n=500 {REFUSAL}" in err[0]
    assert not out.exists()


def test_sweep_identification_sobol_n_500_is_refused_in_one_line(tmp_path, capsys):
    config = tmp_path / "sweep.toml"
    config.write_text('[sweep]\nkind = "leaf"\n\n[identification]\nenabled = true\nsobol_n = 500\n')
    out = tmp_path / "run"
    assert cli.main(["sweep", "--config", str(config), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert f"[identification] sobol_n=500 {REFUSAL}" in err[0]
    assert not out.exists()
