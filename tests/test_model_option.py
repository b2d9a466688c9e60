"""``--model paper | second-order | consistent`` (issue 24): the calibration commands build the
model they name (``cli.opening.calibration_model`` -> ``runs.model_correction.model_space``),
refuse a bad name or a contradicting option in one line, and the form floor says which ran.

The FEM segment provider is replaced by the closed-form one (no FEM cache needed): what is
checked is which space each name builds, not the FEM's numbers."""

import numpy as np
import pytest

from flexcal.geometry.params import reference_mechanism
from flexcal.validation import cli
from flexcal.validation.cli.opening import calibration_model
from flexcal.validation.cli.options import DEFAULT_DIMENSION_TERMS
from flexcal.validation.runs.form_floor import model_description, model_name


@pytest.fixture
def closed_form_segments(monkeypatch):
    """Every provider ``model_space`` asks for by name (``providers.stiffness_provider``: "fem", the
    tied cuts since session 25, or "fem-rigid") -> the analytic segment provider."""
    from flexcal.validation.prototype import providers

    analytic = providers.stiffness_provider("analytic")
    monkeypatch.setattr(providers, "stiffness_provider", lambda kind, **_: analytic)


def _space(*options):
    args = cli.build_parser(only="verify").parse_args(["verify", "--data", "curves.csv", "--out", "o", *options])
    return calibration_model(args, reference_mechanism(), progress=False)


def _parsed(command, *options):
    """The parsed command line of ``command`` with its defaults (no model built, no FEM)."""
    source = {"design": [], "diagnose": ["curves.csv"]}.get(command, ["--data", "curves.csv"])
    return cli.build_parser(only=command).parse_args([command, *source, "--out", "o", *options])


@pytest.mark.parametrize("command", ["verify", "identify", "sensitivity", "design", "diagnose"])
def test_the_calibration_default_is_the_consistent_model(command):
    """Session 20 (issue 24): verify, identify, sensitivity and design calibrate with the
    consistent model unless told otherwise, with the dimension terms of ``DEFAULT_DIMENSION_TERMS``
    (quadratic since session 26); diagnose's baseline since session 28 (docs/diagnosis.md)."""
    from flexcal.validation.cli.opening import dimension_terms, model_option

    args = _parsed(command)
    assert args.model == "consistent" and model_option(args) == "consistent"
    assert args.model_stiffness == "fem" and args.second_order is True and args.breakaway_force is None
    assert args.dimension_terms == DEFAULT_DIMENSION_TERMS and dimension_terms(args) == DEFAULT_DIMENSION_TERMS


def test_compensate_keeps_the_second_order_model():
    # its Tables 2-3 figures were measured with it (its module says so)
    args = _parsed("compensate")
    assert args.model == "second-order" and args.dimension_terms == DEFAULT_DIMENSION_TERMS


def test_second_order_is_selectable_unchanged(closed_form_segments):
    space = _space("--model", "second-order")
    assert model_name(space) == "second-order" and space.second_order and space.compliance_factors
    assert not space.chain_shortening and not space.compliance_slopes and space.breakaway_force is None


def test_quadratic_dimension_terms_by_default_leave_the_other_models_runnable(monkeypatch):
    """The quadratic terms are the default since session 26 (one constant,
    ``DEFAULT_DIMENSION_TERMS``, read by every calibration command's defaults): the consistent
    model takes them, and the models without FEM factors that follow the dimensions run without
    them instead of being refused. With the constant at "linear" (as before) an explicit
    "quadratic" a model cannot take is refused."""
    from flexcal.validation.cli import options
    from flexcal.validation.cli.opening import dimension_terms

    assert options.DEFAULT_DIMENSION_TERMS == "quadratic"
    for command in ("verify", "identify", "sensitivity", "design", "compensate", "diagnose"):
        assert _parsed(command).config["dimension_terms"] == options.DEFAULT_DIMENSION_TERMS, command
    assert dimension_terms(_parsed("verify")) == "quadratic"
    assert dimension_terms(_parsed("verify", "--model", "second-order")) == "linear"
    assert dimension_terms(_parsed("diagnose")) == "quadratic"  # the calibration default since session 28
    assert dimension_terms(_parsed("verify", "--model-stiffness", "closed-form")) == "linear"
    assert dimension_terms(_parsed("verify", "--model", "paper", "--dimension-terms", "linear")) == "linear"
    monkeypatch.setattr(options, "DEFAULT_DIMENSION_TERMS", "linear")
    with pytest.raises(ValueError, match="--model consistent --model-stiffness fem"):
        dimension_terms(_parsed("verify", "--model", "second-order", "--dimension-terms", "quadratic"))


def test_paper_is_the_papers_model(closed_form_segments):
    space = _space("--model", "paper")
    assert model_name(space) == "paper"
    assert not space.second_order and not space.compliance_factors and not space.chain_shortening


def test_the_default_builds_the_consistent_space(closed_form_segments):
    space = _space()  # --model consistent, the default (the parsing: above)
    assert model_name(space) == "consistent" and space.second_order
    assert len(space.chain_shortening) == 36 * 6 and np.all(np.isfinite(space.chain_shortening))
    assert len(space.compliance_slopes) == 40 * 6  # the factors follow the dimensions
    assert space.breakaway_force == 2.0  # the prototype's default, given
    assert _space("--model", "consistent", "--breakaway-force", "5").breakaway_force == 5.0
    assert "(--model consistent)" in model_description(space)


def test_closed_form_consistent_is_eq1s_chains_with_their_own_shortening():
    # no FEM and no prototype code: the factors and the measured shortening correction are left out
    space = _space("--model", "consistent", "--model-stiffness", "closed-form")
    assert model_name(space) == "consistent" and not space.compliance_factors and not space.compliance_slopes
    assert space.chain_shortening == (0.0,) * (36 * 6) and space.breakaway_force == 2.0


def test_the_old_options_still_build_the_papers_model(closed_form_segments):
    # with --model second-order: without it the model is the consistent one, which refuses
    # --no-second-order (the bad-choice cases below)
    space = _space("--model", "second-order", "--model-stiffness", "closed-form", "--no-second-order")
    assert model_name(space) == "paper"


@pytest.mark.parametrize("options, words", [
    (["--model", "consistant"], ["invalid choice", "consistant"]),
    (["--model", "consistent", "--no-second-order"], ["consistent model", "--no-second-order"]),
    (["--model-stiffness", "closed-form", "--no-second-order"], ["calibration default", "--model second-order"]),
    (["--model", "second-order", "--breakaway-force", "3"], ["--breakaway-force", "--model consistent"]),
    (["--model", "consistent", "--breakaway-force", "-1"], ["breakaway_force", ">= 0"]),
], ids=["bad-name", "no-second-order", "old-paper-spelling", "force-without-consistent", "negative-force"])
def test_a_bad_model_choice_is_one_line_and_exit_2(tmp_path, capsys, closed_form_segments, options, words):
    from test_bad_input import write_csv

    rows = [f"{k + 1},{k},0,{0.01 * k:.2f},0,0,{k:.1f},{2 * k:.1f},0.5" for k in range(30)]
    data = write_csv(tmp_path / "curves.csv", rows)
    out = tmp_path / "out"
    status = cli.main(["verify", "--data", str(data), "--skip-unit-check", "--out", str(out), "-q", *options])
    err = capsys.readouterr().err
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    assert all(word in err for word in words), err
    assert not out.exists()


def test_model_stiffness_fem_takes_the_tied_providers_chains(monkeypatch):
    """``--model-stiffness fem`` (issue 26, the default since session 25): the corrections from the
    provider fem (cuts tied), whose
    chains are its ``chain_stiffness`` (here the analytic segments' block diagonal at half the
    stiffness: every factor 2 where the analytic provider's are 1, to their 1e-7 rounding)."""
    import scipy.linalg

    from flexcal.validation.cli.opening import dimension_terms
    from flexcal.validation.prototype import tied_chains
    from flexcal.validation.prototype.segments import analytic_provider, end_stiffness, section_nodes

    def half_stiff(ties, **_):
        segments = analytic_provider()

        def provider(chain, x_start, x_end):
            return segments(chain, x_start, x_end)

        def chain_stiffness(chain):
            nodes = section_nodes(chain)
            return 0.5 * scipy.linalg.block_diag(*(end_stiffness(segments(chain, float(a), float(b)))
                                                   for a, b in zip(nodes[:-1], nodes[1:])))

        provider.chain_stiffness = chain_stiffness
        return provider

    monkeypatch.setattr(tied_chains, "tied_fem_provider", half_stiff)
    space = _space("--model", "second-order", "--model-stiffness", "fem")
    # the analytic factors' rounding (test_model_correction.py: 1e-7), doubled; 1e-6
    np.testing.assert_allclose(np.array(space.compliance_factors), 2.0, rtol=0, atol=1e-6)
    args = _parsed("verify", "--model-stiffness", "fem", "--dimension-terms", "quadratic")
    assert dimension_terms(args) == "quadratic"  # the tied corrections take the quadratic terms too
