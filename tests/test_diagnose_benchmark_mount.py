"""``diagnose-benchmark --mount FILE``: the cases are drawn on the user's mount (its standard
trajectory, its baseline model), their ids differ from the reference mount's, and a null.json
of another mount is refused. The diagnosis is a stub (the real one: test_diagnose)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from flexcal.geometry.mount import mount_table, read_mount
from flexcal.validation import cli
from flexcal.validation.diagnosis.null import NullModel, write_null
from flexcal.validation.reports.safe_markdown import md_text

MIRROR = Path(__file__).resolve().parents[1] / "examples" / "mirror600.mount.toml"


class Stub:
    report = {"top_effect": "none", "top_group": [], "confidence": "none", "noise_floor_urad": 0.5,
              "how_far": {"closure": 0.0}, "ranking": [], "where": {"concentrated": [], "structure": []},
              "collinearity": {"absorbed_by_baseline": {}}, "undetectable": []}


def test_benchmark_cases_are_drawn_on_the_given_mount(tmp_path, monkeypatch, capsys):
    import flexcal.validation.diagnosis.diagnose as diagnose
    from flexcal.validation.diagnosis.benchmark import repeated_trajectory

    seen = []

    def stub(measurement, **options):
        seen.append((measurement, options))
        return Stub()

    monkeypatch.setattr(diagnose, "run_diagnosis", stub)
    mirror = read_mount(MIRROR)
    command = ["diagnose-benchmark", "--grid", "tiny", "--effects", "none", "--workers", "0", "-q"]
    out = tmp_path / "mirror"
    assert cli.main([*command, "--no-null", "--mount", str(MIRROR), "--out", str(out)]) == 0
    # the one case along the mirror's standard trajectory, twice
    inputs, leg = repeated_trajectory(2, None, mirror)
    reference_inputs, _ = repeated_trajectory(2)
    assert not np.allclose(inputs, reference_inputs)  # the mirror's amplitudes are its own
    ((measurement, options),) = seen
    np.testing.assert_allclose(measurement.inputs, inputs, rtol=0, atol=1e-12)  # [m]
    np.testing.assert_array_equal(measurement.leg, leg)
    assert options["baseline"].keywords["space"].mechanism == mirror  # the baseline models the mirror
    (case,) = [json.loads(p.read_text()) for p in (out / "cases").glob("*.json")]
    assert case["spec"]["mount"] == mount_table(mirror)
    report = json.loads((out / "report.json").read_text())
    # the page escapes Markdown's specials in the path (a checkout under /home/j_doe has one)
    assert report["mount"] == str(MIRROR) and f"mount {md_text(str(MIRROR))}" in (out / "report.md").read_text()
    # the reference mount: another case id, no mount in the spec
    assert cli.main([*command, "--no-null", "--out", str(tmp_path / "reference")]) == 0
    (reference,) = [json.loads(p.read_text()) for p in (tmp_path / "reference" / "cases").glob("*.json")]
    assert reference["id"] != case["id"] and "mount" not in reference["spec"]
    # a null of the reference mount's standard trajectory is refused for the mirror, before any case runs
    write_null(tmp_path / "reference" / "null.json", NullModel(n_files=3, trajectory="standard"))
    capsys.readouterr()
    assert cli.main([*command, "--mount", str(MIRROR), "--out", str(tmp_path / "reference")]) == 2
    assert "null of trajectory 'standard', this run's is 'standard on mount " in capsys.readouterr().err
    assert len(seen) == 2


class _Captured(Exception):
    pass


@pytest.mark.parametrize("effect_id", ["sensor_crosstalk", "large_deflection", "step_loss"])
def test_benchmark_effect_sizes_are_scaled_on_the_given_mount(monkeypatch, effect_id):
    """A case's nominal magnitude is the RMS of its signature on the mount it is injected
    into: scaled on the reference mount, the mirror's sensor cross-talk came out 3.9x too
    large and its lost step lay beyond the mirror's path (no signature at all)."""
    import flexcal.validation.prototype.truth as truth
    from flexcal.validation.diagnosis.benchmark import benchmark_measurement
    from flexcal.validation.effects.magnitude import estimate_magnitude, standard_setting

    injected = []

    def capture(scenario, provider, *, effects=(), **options):
        injected.extend(effects)
        raise _Captured

    monkeypatch.setattr(truth, "make_truth", capture)
    mirror = read_mount(MIRROR)
    with pytest.raises(_Captured):
        benchmark_measurement(effect_id, 3.0, 0, provider=None, noise_urad=0.5, mechanism=mirror)
    (effect,) = injected
    achieved = estimate_magnitude(effect, standard_setting(mirror)) * 1e6 / 0.5  # [x noise] on the mirror
    if effect_id == "step_loss":
        assert 1.5 < achieved < 4.5  # whole steps, the event moved along the path to come closest (3.3 here)
    else:
        assert achieved == pytest.approx(3.0, rel=0.011)  # make_injector's secant stops within 1 %


def test_fem_benchmark_builds_the_tied_chains_its_truths_ask_for(monkeypatch):
    """With ``--provider fem`` (tied cuts since session 25) the grid's as-built chains are built
    first through ``segments.prepare_chains`` on the tied provider, not as rigidly joined
    segments the truths never read (the pre-build of sessions 16-25, found in session 26)."""
    import flexcal.validation.prototype.segments as segments
    from flexcal.validation.cli.diagnose_benchmark import run_benchmark

    asked = []

    class Prepared(Exception):
        pass

    def record(provider, chains):
        asked.append((provider, list(chains)))
        raise Prepared  # stop before the cases run: only the pre-build is under test

    monkeypatch.setattr(segments, "prepare_chains", record)
    with pytest.raises(Prepared):
        run_benchmark(["none"], "tiny", noise_urad=0.5, cycles=2, seed=0, progress=False, provider_name="fem",
                      workers=0)
    (provider, chains), = asked
    assert segments.is_tied(provider)
    assert len(chains) % 6 == 0 and chains  # six chains per case's as-built mount
    assert all(type(c).__name__ == "FlexureChain" for c in chains)
