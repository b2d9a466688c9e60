"""The diagnosis baseline's model (issue 28, session 28): ``flexcal diagnose`` and
``diagnose-benchmark`` calibrate the baseline with the calibration commands' model, a case id
and a null file name that model, and a null measured with another model is refused (its gains
are the other model's form error: docs/diagnosis.md, "Issue 28 results (session 27)")."""

import pytest

from flexcal.validation import cli
from flexcal.validation.cli.diagnose_benchmark import case_spec
from flexcal.validation.cli.opening import model_key
from flexcal.validation.diagnosis.null import NullModel, check_null_baseline, read_null, write_null
from flexcal.validation.sweep.space import design_id

CONSISTENT = {"stiffness": "fem", "second_order": True, "model": "consistent", "dimension_terms": "quadratic"}


def _parsed(command, *options):
    source = ["curves.csv"] if command == "diagnose" else []
    return cli.build_parser(only=command).parse_args([command, *source, "--out", "o", *options])


def test_the_diagnosis_baseline_is_the_calibration_default():
    assert model_key(_parsed("diagnose")) == CONSISTENT
    assert model_key(_parsed("diagnose", "--model", "second-order")) == {"stiffness": "fem", "second_order": True}
    assert model_key(_parsed("diagnose", "--breakaway-force", "40")) == {**CONSISTENT, "breakaway_force": 40.0}
    # diagnose-benchmark: the same options, the chains' stiffness the provider's unless given
    benchmark = _parsed("diagnose-benchmark")
    assert benchmark.model == "consistent" and benchmark.model_stiffness is None
    assert benchmark.dimension_terms == "quadratic"


def test_a_case_id_names_the_baseline_model_and_keeps_the_second_order_ids():
    """The second-order baseline's spec is the one of every case before session 28 (so their
    stored rows stay findable); another model gives another id."""
    common = dict(provider_name="fem", noise_urad=0.5, cycles=2, seed=0, scenario_seed=None)
    old = case_spec("drift", 3.0, 0, **common)
    assert old["baseline_model"] == {"stiffness": "fem", "second_order": True}
    assert design_id(case_spec("drift", 3.0, 0, **common, baseline={"stiffness": "fem", "second_order": True})) \
        == design_id(old)
    assert design_id(case_spec("drift", 3.0, 0, **common, baseline=CONSISTENT)) != design_id(old)


def test_a_null_keeps_its_baseline_and_refuses_another(tmp_path):
    path = tmp_path / "null.json"
    write_null(path, NullModel(gain={"drift": 0.2}, n_files=3, baseline=CONSISTENT))
    null = read_null(path)
    assert null.baseline == CONSISTENT and null.gain == {"drift": 0.2}
    check_null_baseline(null, dict(CONSISTENT))  # the same model: accepted
    with pytest.raises(ValueError, match="measured with the baseline model"):
        check_null_baseline(null, {**CONSISTENT, "dimension_terms": "linear"})
    # a null file from before session 28 (no baseline): the second-order model's
    old = NullModel(gain={"drift": 0.2}, n_files=3)
    check_null_baseline(old, {"stiffness": "fem", "second_order": True})
    with pytest.raises(ValueError, match="before session 28"):
        check_null_baseline(old, CONSISTENT)
    path.write_text('{"gain": {}, "n_files": 3, "baseline": "consistent"}')
    with pytest.raises(ValueError, match="not a table of model options"):
        read_null(path)


def test_diagnose_refuses_a_null_of_another_baseline_before_any_calibration(tmp_path, capsys):
    path = tmp_path / "null.json"
    write_null(path, NullModel(gain={"drift": 0.2}, n_files=3))  # the second-order baseline's (no key)
    data = tmp_path / "curves.csv"
    data.write_text("not read: the null is checked first\n")
    assert cli.main(["diagnose", str(data), "--null", str(path), "--out", str(tmp_path / "d")]) == 2
    assert "before session 28" in capsys.readouterr().err and not (tmp_path / "d").exists()
    assert cli.main(["diagnose", str(data), "--null", str(path), "--model", "second-order",
                     "--out", str(tmp_path / "d")]) == 2  # accepted, then the data's own error
    assert "before session 28" not in capsys.readouterr().err
