"""The second example mount (examples/mirror600.mount.toml: 600 x 400 mm mirror, 80 kg,
drives placed unlike the reference's) run end to end on the analytic prototype: truth ->
verify -> compensate -> diagnose, each on the mount the sidecar carries (slow)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from flexcal.geometry.mount import mount_from_table, read_mount
from flexcal.validation import cli

MIRROR = Path(__file__).resolve().parents[1] / "examples" / "mirror600.mount.toml"
QUICK = ["--model-stiffness", "closed-form", "--particles", "40", "--iterations", "10"]  # PSO: > 36 particles


@pytest.mark.slow
def test_second_mount_end_to_end(tmp_path):
    truth, verify, comp, diag = (tmp_path / n for n in ("t", "v", "c", "d"))
    assert cli.main(["truth", "--scenario", "table1", "--mount", str(MIRROR), "--provider", "analytic",
                     "--noise-urad", "0.5", "--out", str(truth), "-q"]) == 0
    sidecar = json.loads((truth / "curves.json").read_text())
    assert mount_from_table(sidecar["mount"], source="sidecar") == read_mount(MIRROR)
    data = str(truth / "curves.csv")
    assert cli.main(["verify", "--data", data, "--noise-urad", "0.5", "--model", "second-order",
                     "--model-stiffness", "closed-form",
                     "--out", str(verify), "-q"]) == 0
    report = json.loads((verify / "report.json").read_text())
    floor = report["model_form_floor"]["models"][0]["all"]["rms_urad"]  # the model at the true values
    floor_rms = float(np.sqrt(np.mean(np.square(list(floor.values())))))
    # the true values are a candidate of the fit, so the estimate fits at least as well; + the 0.5 urad of
    # sensor noise, which the floor (against the noise-free truth) leaves out
    assert report["fit_rms_urad"] <= floor_rms + 0.5
    assert cli.main(["compensate", "--data", data, *QUICK, "--sobol-n", "64", "--max-rounds", "2",
                     "--out", str(comp), "-q"]) == 0
    assert cli.main(["diagnose", data, *QUICK, "--out", str(diag), "-q"]) == 0
    for folder in (verify, comp, diag):
        assert (folder / "report.json").is_file()
