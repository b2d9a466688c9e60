"""The model-form floor (``validation.runs.form_floor``): the model at the true values against
the truth, per angle and per posture group, in every synthetic report."""

import dataclasses
import json

import numpy as np
import pytest

from flexcal.model.forward import forward
from flexcal.model.parameters import parameter_space
from flexcal.model.trajectory import standard_trajectory
from flexcal.validation import cli
from flexcal.validation.runs.form_floor import (GROUP_ORDER, TruthCurve, model_form_floor, paper_model_space,
                                                posture_groups)

ANGLES = ("theta_x", "theta_y", "theta_z")
# The same forward evaluation twice gives the same bits; were the paths to differ, the
# fixed point's tolerance (1e-13 m on u) times the input gain (~5 rad/m) is 5e-13 rad =
# 5e-7 urad: anything above 1e-6 urad is not the model at the true values
SOLVER_URAD = 1e-6


@pytest.fixture(scope="module")
def table1_values():
    from flexcal.validation.prototype.scenario import load_scenario

    return load_scenario("table1").values


@pytest.fixture(scope="module")
def walk_inputs():
    """The standard trajectory, then a 30-point random walk of all three actuators (multi-actuator postures)."""
    rng = np.random.default_rng(0)
    walk = np.cumsum(rng.normal(size=(30, 3)) * 0.1e-3, axis=0)  # [m], ~0.5 mm strokes after 30 steps
    return np.concatenate([standard_trajectory().inputs, walk])


@pytest.mark.parametrize("truth_model", ["second_order", "paper"])
def test_the_matching_model_has_no_floor_and_the_other_has_one(table1_values, walk_inputs, truth_model):
    """A truth made by one model: that model at the true values sits on it (to the solver's
    tolerance), the other does not (the second-order terms move the angles by microradians)."""
    second_order = dataclasses.replace(parameter_space(), second_order=True)
    paper = paper_model_space(second_order)
    maker = second_order if truth_model == "second_order" else paper
    truth = TruthCurve(angles=forward(table1_values, walk_inputs, space=maker).angles[0], presets=table1_values,
                       source="the model itself")
    floor = model_form_floor(truth, walk_inputs, second_order)
    by_model = {m["model"]: m for m in floor["models"]}
    assert set(by_model) == {"run", "paper"} and by_model["paper"]["is_paper_model"]
    matching, other = (by_model["run"], by_model["paper"]) if truth_model == "second_order" else \
        (by_model["paper"], by_model["run"])
    assert matching["all"]["max_urad"] <= SOLVER_URAD  # the solver's tolerance (SOLVER_URAD)
    # measured 3.4 / 3.2 / 0.74 urad RMS between the two models here: 0.3 urad is 10x below that
    assert min(other["all"]["rms_urad"][a] for a in ANGLES) > 0.3


def test_the_paper_model_is_listed_once_when_the_run_used_it(table1_values):
    x = standard_trajectory().inputs
    space = parameter_space()
    truth = TruthCurve(angles=np.zeros_like(x), presets=table1_values, source="zeros")
    floor = model_form_floor(truth, x, space)
    assert [m["model"] for m in floor["models"]] == ["run"] and floor["models"][0]["is_paper_model"]


def test_every_split_pools_to_the_overall_rms(table1_values, walk_inputs):
    """n x RMS^2 of a split's groups add up to the overall one, per angle, for both models
    and for the fit; the groups of a split count every posture once."""
    space = dataclasses.replace(parameter_space(), second_order=True)
    rng = np.random.default_rng(1)
    angles = forward(table1_values, walk_inputs, space=space).angles[0] + rng.normal(size=walk_inputs.shape) * 2e-6
    floor = model_form_floor(TruthCurve(angles=angles, presets=table1_values, source="noisy"), walk_inputs, space,
                             fit_residual=rng.normal(size=walk_inputs.shape) * 1e-6)
    n = walk_inputs.shape[0]
    for block in [*floor["models"], floor["fit"]]:
        overall = block["all"]
        for split, labels in GROUP_ORDER.items():
            groups = [block[split][label] for label in labels]
            assert sum(g["n"] for g in groups) == n
            assert sum(g["n"] > 0 for g in groups) >= 2, split  # the walk has both sides of every split
            for a in ANGLES:
                pooled = np.sqrt(sum(g["n"] * g["rms_urad"][a] ** 2 for g in groups if g["n"]) / n)
                assert pooled == pytest.approx(overall["rms_urad"][a], rel=1e-12)  # float rounding of the sums
            assert max(g["max_urad"] for g in groups if g["n"]) == overall["max_urad"]


def test_posture_groups_by_hand():
    """Five postures: D1 moves alone, then D1 and D2; D3's release changes sign between
    postures 2 and 3 (both near unloading), D2 reverses at posture 4 while its nut is off
    its flank (near), posture 0 is far from any unloading."""
    inputs = np.array([[0, 0, 0], [1e-4, 0, 0], [2e-4, 1e-4, 0], [2e-4, 2e-4, 0], [2e-4, 1e-4, 0]], float)
    release = np.array([[-1, -1, -1], [-1, -1, -1], [-1, 1e-6, -1], [-1, 1e-6, 1e-6], [-1, 1e-6, 1e-6]]) * 1e-5
    directions = np.array([[1, 1, 1], [1, 1, 1], [1, 1, 1], [1, 1, 1], [1, -1, 1]], float)
    groups = posture_groups(inputs, np.array([1, 1, 2, 3, 3]), release, directions)
    assert groups["class"].tolist() == ["S1", "S1", "S2", "S3", "S3"]
    assert groups["actuators"].tolist() == ["single", "single", "multi", "multi", "multi"]
    # D2 flips between 1 and 2 (near: 1, 2), D3 between 2 and 3 (near: 2, 3), D2 reverses at 4 off its flank
    assert groups["unloading"].tolist() == ["far", "near", "near", "near", "near"]


def test_verify_and_identify_reports_carry_the_floor_or_say_not_available(tmp_path):
    """Synthetic data: the floor with its truth named, beside the fit, in report.json and
    report.md; the same curve without its sidecar (a real measurement): "not available"."""
    from flexcal.validation.measurements import read_measurement, write_measurement

    out = tmp_path / "verify"
    assert cli.main(["verify", "--scenario", "table1", "--provider", "analytic", "--model", "second-order",
                     "--model-stiffness", "closed-form",
                     "--method", "paper", "--sobol-n", "16", "--particles", "40", "--iterations", "6", "--out",
                     str(out), "-q"]) == 0
    floor = json.loads((out / "report.json").read_text())["model_form_floor"]
    assert floor["available"] and floor["truth"].startswith("noise-free prototype curve")
    run, paper = floor["models"]
    assert (run["model"], paper["model"]) == ("run", "paper") and "fit" in floor
    # the analytic prototype has the model's chains but exact kinematics and a breakaway band:
    # the second-order model leaves 0.59 / 1.68 / 0.34 urad, the paper's 3.41 / 4.60 / 1.19 (docs/model.md 8)
    assert all(run["all"]["rms_urad"][a] < paper["all"]["rms_urad"][a] for a in ANGLES)
    assert "## Model-form floor" in (out / "report.md").read_text()

    assert cli.main(["truth", "--scenario", "table1", "--provider", "analytic", "--out", str(tmp_path / "t"),
                     "--quiet"]) == 0
    curve = read_measurement(tmp_path / "t" / "curves.csv")
    real = tmp_path / "real"
    real.mkdir()
    write_measurement(real / "curves.csv", type(curve)(point=curve.point, time=curve.time, leg=curve.leg,
                                                        inputs=curve.inputs, angles=curve.angles))
    for data, available in ((tmp_path / "t" / "curves.csv", True), (real / "curves.csv", False)):
        ident = tmp_path / f"identify-{available}"
        assert cli.main(["identify", "--data", str(data), "--model", "second-order",
                         "--model-stiffness", "closed-form", "--particles", "40",
                         "--iterations", "4", "--out", str(ident), "-q"]) == 0
        floor = json.loads((ident / "report.json").read_text())["model_form_floor"]
        text = (ident / "report.md").read_text()
        assert floor["available"] is available
        if available:
            assert floor["truth"].startswith("measured curve, noise-free")  # the table1 sidecar states noise 0
            assert {m["model"] for m in floor["models"]} == {"run", "paper"}
        else:
            assert floor["reason"].startswith("not available: no true values")
            assert "not available: no true values" in text
