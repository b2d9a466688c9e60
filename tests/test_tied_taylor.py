"""prototype.tied_taylor: the model's moved tied chains from their nominal chain's segment
derivatives, against the nominal chain's own build and the moved chains condensed in full on
the nominal cells."""

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

THROUGH = 1  # the coarsest mapped grid: the composition does not depend on it, the test's time does


@pytest.fixture(scope="module")
def setting(tmp_path_factory):
    """(tied provider, Taylor provider, table1's D1, its mechanism's space) on one fresh cache."""
    from flexcal.model.parameters import parameter_space
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.tied_chains import tied_fem_provider
    from flexcal.validation.prototype.tied_taylor import taylor_tied_provider

    space = parameter_space(load_scenario("table1").space.mechanism)
    nominal = space.mechanism.chains[3].chain
    base = tied_fem_provider(elements_through_thickness=THROUGH, cache_directory=tmp_path_factory.mktemp("cache"),
                             progress=False)
    return base, taylor_tied_provider(base, [nominal]), nominal, space


def test_a_nominal_chain_comes_from_its_polynomials_at_zero_with_its_builds_bits(setting):
    import dataclasses

    from flexcal.validation.prototype.tied_chains import tied_fem_provider
    from flexcal.validation.prototype.tied_taylor import segment_taylors, taylor_chain_matrices, taylor_tied_provider

    base, _, nominal, _ = setting
    asked = []
    spied = tied_fem_provider(elements_through_thickness=THROUGH, cache_directory=base.cache_directory, progress=False)
    own = spied.chain_stiffness
    spied.chain_stiffness = lambda chain: asked.append(chain) or own(chain)
    taylor = taylor_tied_provider(spied, [nominal])
    assert np.array_equal(taylor.chain_stiffness(nominal), base.chain_stiffness(nominal))
    assert asked == []  # served by the polynomials, not built
    twin = dataclasses.replace(nominal, length=np.nextafter(nominal.length, 1.0))  # as the mount's L2 and L1
    # a 1-ulp longer chain meshes to the same nodes: its build is its twin's to the bit (so are
    # table1's L1 and L2 on the prototype's grid, measured), and the polynomials give it too
    assert np.array_equal(taylor.chain_stiffness(twin), base.chain_stiffness(twin))
    assert asked == []
    taylors = segment_taylors(nominal, base.ties, elements_through_thickness=THROUGH,
                              cache_directory=base.cache_directory)
    at_zero = taylor_chain_matrices(nominal, nominal, taylors, base.ties)
    assert np.array_equal(at_zero["stiffness"], base.chain_stiffness(nominal))
    assert np.array_equal(at_zero["segments"], base.chain_segments(nominal))


@pytest.mark.parametrize("moves", [{"w": 0.003}, {"l": -0.003}, {"t1": 0.003, "a": 0.003}])
def test_a_moved_chain_is_the_full_condensation_on_the_nominal_cells(setting, moves):
    """At the 0.3 % steps the dimension terms take (``DIFFERENCE_STEP``) the polynomial's remainder
    is what their differences divide by the step: 1e-3 of the move's own change keeps every slope
    within 0.1 %. Measured on this grid: 1.0e-4 of the change for l (1.0e-6 of the compliance
    against 9.8e-3; 1.7e-7 at 0.1 %), less for the others."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_morphed_terms import morphed_tied_provider

    from flexcal.validation.runs.model_correction import moved_chain, provider_chain_compliance

    base, taylor, nominal, space = setting
    morphed = morphed_tied_provider(base, space, 1e-4, "template")
    chain = moved_chain(nominal, moves)
    C0 = provider_chain_compliance(nominal, base)
    full = provider_chain_compliance(chain, morphed)
    scale = np.sqrt(np.abs(np.outer(np.diag(C0), np.diag(C0))))
    change = np.max(np.abs(full - C0) / scale)
    assert change > 1e-3  # the move is seen (~1e-2 at 0.3 %)
    # 1e-3 of the change: every slope the terms take from it within 0.1 % (docstring)
    assert np.max(np.abs(provider_chain_compliance(chain, taylor) - full) / scale) < 1e-3 * change


def test_a_chain_moved_beyond_the_reach_or_in_another_field_is_built(setting):
    import dataclasses

    from flexcal.validation.prototype.tied_taylor import TAYLOR_REACH, relative_dimensions

    _, _, nominal, _ = setting
    itself = relative_dimensions(nominal, [nominal])
    assert itself[0] is nominal and np.array_equal(itself[1], np.zeros(5))
    # a rounding twin (the mount's L2 is 1 ulp longer than L1) is its nominal chain at r = 0
    twin = dataclasses.replace(nominal, length=np.nextafter(nominal.length, 1.0))
    assert twin != nominal and np.array_equal(relative_dimensions(twin, [nominal])[1], np.zeros(5))
    far = dataclasses.replace(nominal, width=nominal.width * (1 + 2 * TAYLOR_REACH))
    assert relative_dimensions(far, [nominal]) is None
    longer = dataclasses.replace(nominal, length=nominal.length * 1.001)  # not a dimension term's move
    assert relative_dimensions(longer, [nominal]) is None
    found = relative_dimensions(dataclasses.replace(nominal, width=nominal.width * 1.003), [nominal])
    # r = width / nominal width - 1: one rounding of the ratio, ~1e-16
    assert found is not None and np.allclose(found[1], [0.003, 0, 0, 0, 0], rtol=0, atol=1e-15)


def test_the_model_provider_takes_the_derivatives_by_default_and_the_builds_on_request():
    from flexcal.validation.prototype.tied_taylor import DIFFERENCE_STEP
    from flexcal.validation.runs.model_correction import SLOPE_STEPS, difference_steps, model_provider

    derived = model_provider("fem", None, progress=False)
    built = model_provider("fem", None, chains="builds", progress=False)
    assert set(difference_steps(derived).values()) == {DIFFERENCE_STEP}
    assert difference_steps(built) == SLOPE_STEPS
    assert difference_steps(model_provider("fem-rigid", None, progress=False)) == SLOPE_STEPS  # not tied
    with pytest.raises(ValueError, match="term chains"):
        model_provider("fem", None, chains="nope")
