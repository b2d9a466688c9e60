"""Issue 28's diagnosis: the measurement chain's effects (sensor settling, air turbulence),
the null of a trajectory, and the look-alike test of `high` confidence (docs/diagnosis.md,
docs/effects.md). Analytic prototype, 0.5 urad noise."""

import numpy as np
import pytest

from flexcal.validation.diagnosis.benchmark import benchmark_measurement
from flexcal.validation.diagnosis.diagnose import library_terms, run_diagnosis
from flexcal.validation.diagnosis.null import NullModel, null_from_reports
from flexcal.validation.effects.chain import AirTurbulence, SensorSettling, ar1_series, settling_error
from flexcal.validation.effects.library import EFFECT_IDS, make_injector, model_term
from flexcal.validation.prototype.segments import analytic_provider


@pytest.fixture(scope="module")
def provider():
    return analytic_provider()


def test_settling_error_is_a_first_order_response():
    """One jump of 1 mrad after a 2 s dwell: the reading misses exp(-2 s / tau) of it; averaged
    over the last 0.5 s of the dwell, the mean of the exponential over that window."""
    angles = np.array([[0.0, 0.0, 0.0], [1e-3, -2e-3, 0.0]])
    time = np.array([0.0, 2.0])
    error = settling_error(angles, time, 0.5)
    # exp of a float: exact to round-off
    np.testing.assert_allclose(error[1], -np.array([1e-3, -2e-3, 0.0]) * np.exp(-4.0), rtol=1e-12)
    from scipy.integrate import quad

    window = quad(lambda u: np.exp(-u / 0.5), 1.5, 2.0)[0] / 0.5  # the window average by quadrature
    # quad's error estimate is ~1e-15 relative here: 1e-9 leaves room for the closed form's round-off
    np.testing.assert_allclose(settling_error(angles, time, 0.5, 0.5)[1], -angles[1] * window, rtol=1e-9)
    # the hook of the prototype reads the same from the history
    from flexcal.validation.effects.hooks import EffectContext, PointResult

    previous = PointResult(angles=angles[0], pose=np.zeros(6), axial_loads=np.zeros(6), nut_offsets=np.zeros(3))
    context = EffectContext(point_index=1, command=np.zeros(3), direction=np.ones(3), previous=previous, time=2.0,
                            dwell=2.0, past_commands=np.zeros((2, 3)), past_times=time, history=(previous,))
    measured = SensorSettling(time_constant=(0.5, 0.5, 0.5)).measure(angles[1].copy(), context)
    np.testing.assert_allclose(measured - angles[1], error[1], rtol=1e-12)  # the same formula


def test_turbulence_is_a_causal_unit_ar1_series():
    """The series of the first k points does not change when later points are added (the hook
    is called point by point), and its lag-1 correlation is exp(-dt / tau_c)."""
    time = np.arange(20000) * 2.0
    series = ar1_series(time, 60.0, seed=3)
    np.testing.assert_array_equal(ar1_series(time[:50], 60.0, seed=3), series[:50])
    # 20000 AR(1) samples, phi = exp(-1/30): the variance's standard error is
    # sqrt(2 (1 + phi^2) / (1 - phi^2) / 20000) = 0.055, so 3 of them
    assert np.var(series, axis=0) == pytest.approx(np.ones(3), abs=0.17)
    lag1 = [np.corrcoef(series[:-1, c], series[1:, c])[0, 1] for c in range(3)]
    # the lag-1 correlation's standard error is sqrt((1 - phi^2) / 20000) = 0.0018, so 3 of them
    assert lag1 == pytest.approx([np.exp(-2.0 / 60.0)] * 3, abs=0.0055)
    assert AirTurbulence(sd=(1e-6, 0, 0), correlation_time=60.0).parameters["correlation_time"] == 60.0


def test_new_effects_are_library_entries_with_injector_and_term():
    for effect_id in ("sensor_settling", "air_turbulence"):
        assert effect_id in EFFECT_IDS
        term = model_term(effect_id)
        injector = make_injector(effect_id, 1.5, 0)
        assert injector.name == effect_id and term.id == effect_id


def test_null_raises_a_terms_threshold_by_its_gain_on_none_files():
    reports = [{"ranking": [{"effect": "large_deflection", "gain_noise_variances": 3.9, "closure": 0.93},
                            {"effect": "drift", "gain_noise_variances": -0.3, "closure": -0.07}]},
               {"ranking": [{"effect": "large_deflection", "gain_noise_variances": 2.0, "closure": 0.6},
                            {"effect": "drift", "gain_noise_variances": 0.1, "closure": 0.02}]}]
    null = null_from_reports(reports, "abc")
    assert null.gain == {"large_deflection": 3.9, "drift": 0.1} and null.n_files == 2
    assert null.min_gain("large_deflection", 1.0) == pytest.approx(3 * 3.9)  # NULL_FACTOR x the largest
    assert null.min_gain("drift", 1.0) == 1.0 and null.min_gain("thermal", 1.0) == 1.0  # the floor
    assert NullModel().min_gain("x", 1.0) == 1.0


@pytest.mark.slow  # 65-142 s each (a diagnosis with the look-alike test; 142 s: air_turbulence at load 10)
@pytest.mark.parametrize("effect_id", ["sensor_settling", "air_turbulence"])
def test_each_new_effect_is_found_on_its_own_injection(provider, effect_id):
    """At 10x the noise on the standard trajectory x2, the new effect is the top effect or in
    its group (without its term the library has nothing for it: checked by the look-alike test).
    air_turbulence was an expected failure until session 18: no term closed its held-out gap
    (its cosines -0.39); now the correlated-noise test names it, `low` (docs/diagnosis.md)."""
    case = benchmark_measurement(effect_id, 10.0, 0, provider)
    report = run_diagnosis(case.measurement, rng=0).report
    assert effect_id == report["top_effect"] or effect_id in report["top_group"], report["ranking"][:3]
    if effect_id == "air_turbulence":
        assert report["detected_by"] == "correlated noise" and report["confidence"] == "low"


@pytest.mark.slow  # 396 s at load 10 (2026-11-28): the 77-point design (107 s idle) and a diagnosis
def test_air_turbulence_10x_on_the_designed_trajectory_is_found(tmp_path, provider):
    """The case the designed small grid missed in session 17 (docs/diagnosis.md: air_turbulence 10x
    on design e8991e922cac40a3 answered `none`, its cosine term closing 0.24 < 0.25): the
    correlated-noise test names it, `low` (the grid's `none` files stay `none`: docs/diagnosis.md)."""
    from flexcal.validation import cli
    from flexcal.validation.diagnosis.benchmark import trajectory_digest
    from flexcal.validation.prototype.scenario import read_trajectory

    assert cli.main(["design", "--model", "second-order", "--points", "77", "--model-stiffness", "closed-form", "--out",
                     str(tmp_path / "design"), "-q"]) == 0
    trajectory = read_trajectory(tmp_path / "design" / "trajectory.csv")
    assert trajectory_digest(*trajectory) == "e8991e922cac40a3"  # the grid's design: the same case
    case = benchmark_measurement("air_turbulence", 10.0, 0, provider, trajectory=trajectory)
    report = run_diagnosis(case.measurement, rng=0).report
    assert report["top_effect"] == "air_turbulence", (report["ranking"][:3], report["correlated_noise"])
    assert report["confidence"] == "low" and report["detected_by"] == "correlated noise"
    # p measured 4e-16 (z 8.0); far from the 1e-3 threshold, so a regression shows as a miss, not as noise
    assert report["correlated_noise"]["p_value"] < 1e-6


def _small_design(folder):
    """A 41-posture ``flexcal design`` trajectory (300 candidates, no inadequacy weight: seconds);
    along it the second-order baseline misses the prototype where large rotations combine, as on
    the 77-point design of docs/diagnosis.md (large_deflection `high` on its `none` files)."""
    from flexcal.validation import cli
    from flexcal.validation.prototype.scenario import read_trajectory

    assert cli.main(["design", "--model", "second-order",
                     "--points", "41", "--candidates", "300", "--model-stiffness", "closed-form",
                     "--inadequacy", "none", "--out", str(folder), "-q"]) == 0
    return read_trajectory(folder / "trajectory.csv")


@pytest.mark.slow  # ~160 s: a design, three null files and a diagnosis
def test_designed_trajectory_none_file_gives_no_false_alarm(tmp_path, provider):
    """A `none` file along a designed trajectory (x2): with the trajectory's null (the terms'
    gains on three other `none` files along it, as diagnose-benchmark makes it) nothing is named.
    Without the null the same file names large_deflection with `high` confidence (closure 0.81,
    gain 7.8 noise variances; measured, docs/diagnosis.md)."""
    from flexcal.validation.diagnosis.null import NULL_SEEDS, measure_null

    trajectory = _small_design(tmp_path / "design")

    def make(seed):
        return benchmark_measurement("none", 0.0, seed, provider, trajectory=trajectory).measurement

    null = measure_null(make, lambda m: run_diagnosis(m, rng=0), NULL_SEEDS, "design-41")
    report = run_diagnosis(make(0), rng=0, null=null).report
    assert report["top_effect"] == "none", report["ranking"][:3]
    assert report["confidence"] == "none"
    assert report["null"]["min_gain"]["large_deflection"] > 1.0  # the form error raised its threshold


@pytest.mark.slow  # ~70 s
def test_lookalike_out_of_the_library_is_not_claimed_with_high_confidence(provider):
    """A first-order sensor lag (10x the noise) diagnosed with the library of before issue 28,
    which has no term for it: creep's free time constant imitates it (closure 0.77, with
    coupling_windup at 0.67 close behind) and was named with `high` confidence. Now the
    winner is not separated from its look-alikes: `low`."""
    case = benchmark_measurement("sensor_settling", 10.0, 0, provider)
    terms = [t for t in library_terms(case.measurement.extras)[0] if t.id not in ("sensor_settling", "air_turbulence")]
    report = run_diagnosis(case.measurement, rng=0, terms=terms).report
    assert report["top_effect"] != "none"  # something is claimed (the lag is 10x the noise)...
    assert report["confidence"] == "low", (report["top_effect"], report["separation"])  # ...but not with confidence
    assert report["separation"] is not None and not report["separation"]["separated"]


def test_benchmark_command_measures_the_null_first_and_keeps_it(tmp_path, monkeypatch, capsys):
    """diagnose-benchmark diagnoses the null's `none` files (seeds 100-102) before the cases,
    keeps DIR/null.json, passes the null to every case's diagnosis and reuses the file on a
    rerun. The diagnosis is a stub here (the real one: the designed-trajectory test above)."""
    import json

    import flexcal.validation.diagnosis.diagnose as diagnose
    from flexcal.validation import cli

    calls = []

    class Stub:
        def __init__(self, gain):
            self.report = {"top_effect": "none", "top_group": [], "confidence": "none", "noise_floor_urad": 0.5,
                           "how_far": {"closure": 0.0}, "where": {"concentrated": [], "structure": []},
                           "ranking": [{"effect": "large_deflection", "gain_noise_variances": gain, "closure": 0.5,
                                        "delta_bic": 0.0, "significant": False}],
                           "collinearity": {"absorbed_by_baseline": {}}, "undetectable": []}

    def stub(measurement, null=None, **_):
        calls.append(null)
        return Stub(float(len(calls)))  # gains 1, 2, 3 on the three null files

    monkeypatch.setattr(diagnose, "run_diagnosis", stub)
    out = tmp_path / "bench"
    command = ["diagnose-benchmark", "--grid", "tiny", "--effects", "none", "--workers", "0", "-q", "--out", str(out)]
    assert cli.main(command) == 0
    assert calls[:3] == [None, None, None] and len(calls) == 4  # three null files without a null, then the case
    null = json.loads((out / "null.json").read_text())
    assert null["gain"] == {"large_deflection": 3.0} and null["n_files"] == 3
    assert calls[3].min_gain("large_deflection", 1.0) == 9.0  # 3x the largest null gain
    assert json.loads((out / "report.json").read_text())["null"]["gain"] == {"large_deflection": 3.0}
    (out / "cases").rename(tmp_path / "old-cases")  # rerun the case: the null is read, not measured again
    assert cli.main(command) == 0 and len(calls) == 5 and calls[4].gain == {"large_deflection": 3.0}
    # the null keeps the baseline model it was measured with (the calibration default since
    # session 28; closed-form chains as the analytic prototype's), and another model refuses it
    assert null["baseline"] == {"stiffness": "closed-form", "second_order": True, "model": "consistent",
                                "dimension_terms": "linear"}
    assert cli.main([*command, "--model", "second-order"]) == 2 and len(calls) == 5
    assert "measured with the baseline model" in capsys.readouterr().err
