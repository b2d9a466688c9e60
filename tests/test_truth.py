"""Scenarios, synthetic truth and ``flexcal truth`` (virtual prototype, analytic segment
stiffness for speed; the FEM-provider runs are marked slow)."""

import json

import numpy as np
import pytest

from flexcal.model.forward import forward, ideal_angles
from flexcal.model.parameters import parameter_space
from flexcal.validation import cli
from flexcal.validation.measurements import read_measurement
from flexcal.validation.prototype.scenario import TABLE1_PRESETS, load_scenario
from flexcal.validation.prototype.segments import analytic_provider
from flexcal.validation.prototype.truth import as_built, make_truth

SPACE = parameter_space()


def test_table1_presets_and_draws_within_bounds():
    scenario = load_scenario("table1")
    for name, value in TABLE1_PRESETS.items():
        param = SPACE.parameter(name)
        # display units and back: round-off only
        assert scenario.values[SPACE.index(name)] == pytest.approx(value / param.display_scale, rel=1e-12)
    lower = np.array([p.lower for p in SPACE.parameters])
    upper = np.array([p.upper for p in SPACE.parameters])
    assert np.all((scenario.values >= lower) & (scenario.values <= upper))
    assert np.all(scenario.noise == 0.0)  # like the paper's simulation: noise-free unless asked
    other = load_scenario("table1", seed=2)
    drawn = [i for i, p in enumerate(SPACE.parameters) if p.name not in TABLE1_PRESETS]
    assert not np.allclose(scenario.values[drawn], other.values[drawn])
    np.testing.assert_array_equal(load_scenario("table1").values, scenario.values)


def test_scenario_file_and_its_errors(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('name = "mine"\nseed = 3\ndraw_unset = false\n[errors]\n"D3.CL" = 0.2\n'
                    '[sensors]\nnoise_urad = [0.5, 0.5, 1.0]\n[trajectory]\nn_points = 13\n')
    scenario = load_scenario(str(path))
    assert scenario.inputs.shape == (13, 3)
    np.testing.assert_allclose(scenario.noise, [0.5e-6, 0.5e-6, 1.0e-6])
    assert scenario.values[SPACE.index("D3.CL")] == pytest.approx(0.2e-3)
    assert scenario.values[SPACE.index("L1.w")] == SPACE.parameter("L1.w").nominal
    for text, words in [('[errors]\n"D3.CL" = 0.9\n', ["D3.CL", "out of range"]),
                        ('[errors]\n"D9.CL" = 0.1\n', ["D9.CL"]),
                        ('colour = "red"\n', ["unknown key", "colour"]),
                        ('[trajectory]\nkind = "spiral"\n', ["spiral"])]:
        path.write_text(text)
        with pytest.raises(ValueError) as info:
            load_scenario(str(path))
        for word in words:
            assert word in str(info.value)
    with pytest.raises(FileNotFoundError, match="neither a built-in"):
        load_scenario(str(tmp_path / "missing.toml"))


def test_as_built_applies_every_source():
    values = SPACE.build_values({"D2.t1": 3.2, "L3.d": 1.5, "L3.phi": 1.0, "D1.x0": 0.1, "D1.CL": 0.2,
                                 "D1.mu": 0.8}, display_units=True)
    mechanism, offsets, drives = as_built(SPACE, values)
    assert mechanism.chains[4].chain.thickness_1 == pytest.approx(3.2e-3)
    assert offsets["L3"] == pytest.approx((1.5e-3, 1.0))
    assert drives[0] == pytest.approx((0.1e-3, 0.2e-3, 0.8))


@pytest.fixture(scope="module")
def nominal_truth():
    return make_truth(load_scenario("nominal"), analytic_provider())


def test_prototype_matches_model_without_errors(nominal_truth):
    """Nominal mechanism, no clearance, same (analytic) chain stiffness: the prototype's
    exact kinematics against the model's Taylor parasitic term. Measured 4.6 / 2.9 / 2.6
    urad max (theta x / y / z); 6 urad bounds the second-order terms the model drops
    (rotation vector vs small-angle twist ~ theta^2 / 2 with theta <= 3.5 mrad is ~6 urad)."""
    truth = nominal_truth.measurement
    model = forward(SPACE.nominal_full, truth.inputs).angles[0]
    difference = np.abs(truth.angles - model).max(axis=0)
    # bound on the second-order terms the model drops (docstring; measured 4.6 urad)
    assert np.all(difference < 6e-6), difference * 1e6
    # and the misalignment against the ideal (linear) model is much larger than that: the
    # parasitic motion and gravity the ideal model leaves out
    assert np.abs(truth.angles - ideal_angles(truth.inputs)).max() > 3 * difference.max()
    assert np.max(nominal_truth.run.force_residual) < 1e-4  # Newton residual [N], stated in docs/prototype.md


def test_same_seed_same_file_and_noise_level(tmp_path):
    scenario = load_scenario("table1", noise_urad=0.5)
    first = make_truth(scenario, analytic_provider()).measurement
    second = make_truth(load_scenario("table1", noise_urad=0.5), analytic_provider()).measurement
    np.testing.assert_array_equal(first.angles, second.angles)
    clean = make_truth(load_scenario("table1"), analytic_provider()).measurement
    noise = (first.angles - clean.angles).ravel()
    # 231 samples of N(0, 0.5 urad): the sample std is within +-20 % with probability > 0.999
    assert 0.4e-6 < noise.std() < 0.6e-6
    classes = set(make_truth(load_scenario("table1"), analytic_provider()).run.point_class)
    assert "S2" in classes  # D3 goes into tension near reversals and its nut crosses the gap


def test_truth_command_writes_files_and_rejects_bad_input(tmp_path, capsys):
    out = tmp_path / "run"
    assert cli.main(["truth", "--scenario", "table1", "--provider", "analytic", "--out", str(out), "--quiet"]) == 0
    measurement = read_measurement(out / "curves.csv")
    assert measurement.n_points == 77
    sidecar = json.loads((out / "curves.json").read_text())
    assert sidecar["scenario"] == "table1" and len(sidecar["preset_errors"]) == 45
    assert (out / "curves.png").stat().st_size > 10_000
    bad = tmp_path / "bad"
    assert cli.main(["truth", "--scenario", "table1", "--noise-urad", "-1", "--out", str(bad)]) == 2
    assert "must be >= 0" in capsys.readouterr().err
    assert not bad.exists()


@pytest.mark.slow
def test_fem_prototype_matches_model_within_the_chain_discrepancy(tmp_path):
    """Issue 4's check with the FEM segments: no errors, no clearance. The prototype then
    differs from the model by the chain-stiffness gap of docs/model-vs-fem.md (axial
    +37..41 %, torsion -77..81 %, working bending <= 3 %) plus the kinematic terms above.
    Measured 13.5 / 10.5 / 2.8 urad max; the bound 25 urad is under 1 % of the standard
    trajectory's theta_y travel (+-3.2 mrad) and would catch a wrong segment frame or DOF
    order, which give hundreds of urad."""
    from flexcal.validation.prototype.fem_provider import fem_provider

    truth = make_truth(load_scenario("nominal"), fem_provider(cache_directory=tmp_path, progress=False))
    model = forward(SPACE.nominal_full, truth.measurement.inputs).angles[0]
    difference = np.abs(truth.measurement.angles - model).max(axis=0)
    assert np.all(difference < 25e-6), difference * 1e6  # docstring: measured 13.5 urad; wrong frames give hundreds
    assert np.max(truth.run.force_residual) < 1e-4  # Newton residual [N], stated in docs/prototype.md


# issue 14: a user scenario holding only a name draws all 45 sources within their full
# ranges; seeds 1 and 3 stopped at points 19 and 20 ("nut offsets ... did not converge"):
# two driving chains in their clearance make the plain fixed point contract by ~0.7 per
# round. Anderson acceleration (validation/prototype/fixed_point.py) settles them.
@pytest.mark.parametrize("seed", [1, 3])
def test_user_scenario_with_only_a_name_converges(tmp_path, seed):
    scenario = tmp_path / "x.toml"
    scenario.write_text('name = "x"\n')
    out = tmp_path / "out"
    assert cli.main(["truth", "--scenario", str(scenario), "--seed", str(seed), "--provider", "analytic",
                     "--out", str(out), "-q"]) == 0
    assert read_measurement(out / "curves.csv").n_points == 77


def test_offsets_that_do_not_settle_name_the_knob(tmp_path, capsys, monkeypatch):
    import flexcal.validation.prototype.mechanism as prototype

    def damped_only(iterates, images, upper, **_):  # the plain damped iteration of before
        return np.clip(0.5 * (iterates[-1] + images[-1]), 0.0, upper), False

    monkeypatch.setattr(prototype, "anderson_step", damped_only)
    scenario = tmp_path / "x.toml"
    scenario.write_text('name = "x"\n')
    out = tmp_path / "out"
    status = cli.main(["truth", "--scenario", str(scenario), "--seed", "1", "--provider", "analytic",
                       "--out", str(out)])
    # stderr is not a terminal under pytest: the progress lines ("[  0.1 s] ...") come too
    err = "\n".join(line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("["))
    assert status == 2 and len(err.splitlines()) == 1, err
    for words in ("did not converge at point 19", "'D1.mu', 'D1.CL'", "'D2.mu', 'D2.CL'", "[errors]", "--seed"):
        assert words in err, (words, err)
    assert not out.exists()
