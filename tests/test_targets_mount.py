"""Compensation targets lie in the data's mount's workspace (validation/runs/targets.py), not
the reference mount's: the default set spans the mount's box, a file is checked against it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flexcal.geometry.mount import read_mount
from flexcal.validation import cli
from flexcal.validation.runs.targets import default_targets, read_targets

MIRROR = Path(__file__).resolve().parents[1] / "examples" / "mirror600.mount.toml"


def targets_file(path: Path, theta_x_urad: float) -> Path:
    path.write_text(f"theta_x_urad,theta_y_urad,theta_z_urad\n{theta_x_urad},0,0\n")
    return path


def test_targets_follow_the_given_workspace(tmp_path):
    mirror = read_mount(MIRROR)  # workspace +-2, 4, 4 mrad; the reference's +-1, 5, 3 mrad
    spread = np.max(np.abs(default_targets(workspace=mirror.workspace)), axis=0)
    # 30 Halton points over +-80 % of the box reach past 70 % of it on every axis, never past 80 %
    assert np.all(spread <= 0.8 * np.asarray(mirror.workspace) * (1 + 1e-12))  # 1e-12: the scaling's round-off
    assert np.all(spread >= 0.7 * np.asarray(mirror.workspace))  # 0.7: the Halton points' reach, as above
    wide = targets_file(tmp_path / "t.csv", 1500.0)  # inside the mirror's theta_x range, outside the reference's
    assert read_targets(wide, workspace=mirror.workspace)[0, 0] == pytest.approx(1.5e-3, rel=1e-12)  # urad -> rad round-off
    with pytest.raises(ValueError, match=r"outside the workspace \+-\[1000, 5000, 3000\] urad"):
        read_targets(wide)


def test_compensate_checks_targets_against_the_data_mount(tmp_path, capsys):
    data = tmp_path / "mirror"
    assert cli.main(["truth", "--scenario", "nominal", "--mount", str(MIRROR), "--provider", "analytic",
                     "--out", str(data), "-q"]) == 0
    outside = targets_file(tmp_path / "far.csv", 2500.0)  # beyond the mirror's +-2 mrad
    capsys.readouterr()
    assert cli.main(["compensate", "--data", str(data / "curves.csv"), "--targets", str(outside),
                     "--model-stiffness", "closed-form", "--out", str(tmp_path / "c")]) == 2
    assert "outside the workspace +-[2000, 4000, 4000] urad" in capsys.readouterr().err
