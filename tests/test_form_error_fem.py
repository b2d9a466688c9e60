"""Issue 24's form-error goal against the FEM prototype: the consistent model (docs/model.md 10)
with the FEM compliance factors following the dimensions (``compliance_slopes``, docs/model.md 7)
at the true values of `table1`, on a random multi-actuator walk, at two breakaway forces.

Slow (15 s warm): the FEM segments of the as-built chains and of the nominal chains at +-step per dimension
(the slopes) are cached in ~/.cache/flexcal; cold, they are ~100 segment builds."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from flexcal.model import kernel
from flexcal.model.forward import forward
from flexcal.model.trajectory import standard_trajectory

from test_model_play import N_WALK, STROKE, WALK_SEED, random_walk

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not kernel.available(), reason="the consistent model runs in the compiled engine")]


@pytest.fixture(scope="module")
def table1_fem():
    """`table1`, its consistent space with FEM factors and slopes (measured at nominal), a
    40-point multi-actuator walk and the FEM prototype's curves along it at 2 and 5 N."""
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import make_truth
    from flexcal.validation.runs.chain_kinematics import consistent_space
    from flexcal.validation.runs.model_correction import corrected_space

    scenario = load_scenario("table1")
    provider = stiffness_provider("fem", progress=False, workers=None)
    inputs = random_walk(standard_trajectory(scenario.space.mechanism).amplitudes, N_WALK, STROKE, WALK_SEED)
    curves = {force: make_truth(dataclasses.replace(scenario, inputs=inputs, leg=np.ones(N_WALK, dtype=int),
                                                    breakaway_force=force), provider).run.angles
              for force in (2.0, 5.0)}
    space = consistent_space(corrected_space(scenario.space, provider, slopes=True), provider)
    return scenario, space, inputs, curves


def _rms_urad(error):
    return np.sqrt(np.mean(error**2, axis=0)) * 1e6


@pytest.mark.parametrize("force", [2.0, 5.0])
def test_the_consistent_model_with_slopes_meets_the_goal_on_the_fem_prototype(table1_fem, force):
    scenario, space, inputs, curves = table1_fem
    with_slopes = dataclasses.replace(space, breakaway_force=force)
    new = _rms_urad(forward(scenario.values, inputs, space=with_slopes).angles[0] - curves[force])
    constant = _rms_urad(forward(scenario.values, inputs, space=dataclasses.replace(
        with_slopes, compliance_slopes=())).angles[0] - curves[force])
    # 0.25 urad per angle is issue 24's goal; measured here 0.039 / 0.071 / 0.002 urad at both
    # forces with the slopes, 0.37 / 0.20 / 0.03 with the factors held at nominal (on
    # bench_form_error's standard trajectories and walks <= 0.05 / 0.13 / 0.03, both mounts,
    # docs/model.md 11)
    assert np.all(new <= 0.25), new
    assert np.any(constant > 0.25), constant  # the same bound fails with the constant factors


DESIGN = Path(__file__).parent / "data" / "table1_design_k41_drives.csv"


@pytest.fixture(scope="module")
def table1_design():
    """`table1` along a `flexcal design` trajectory (tests/data/table1_design_k41_drives.csv:
    the 41 standard postures + 36 of `--criterion drives`, designed at a seed-1 estimate in
    session 26), its consistent space with linear and with quadratic dimension terms, and the
    FEM prototype's curves along it at 2 and 5 N. Cold: ~40 tied chains for the model's terms."""
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario, read_trajectory
    from flexcal.validation.prototype.truth import make_truth
    from flexcal.validation.runs.chain_kinematics import consistent_space
    from flexcal.validation.runs.dimension_terms import curved_space
    from flexcal.validation.runs.model_correction import corrected_space

    scenario = load_scenario("table1")
    provider = stiffness_provider("fem", progress=False, workers=None)
    inputs, leg = read_trajectory(DESIGN)
    curves = {force: make_truth(dataclasses.replace(scenario, inputs=inputs, leg=leg, breakaway_force=force),
                                provider).run.angles for force in (2.0, 5.0)}
    linear = consistent_space(corrected_space(scenario.space, provider, slopes=True), provider)
    return scenario, linear, curved_space(linear, provider), inputs, curves


@pytest.mark.parametrize("force", [2.0, 5.0])
def test_the_quadratic_dimension_terms_meet_the_goal_on_a_design(table1_design, force):
    """The default dimension terms since session 26 (docs/model.md 11, "Session 26"): on a designed
    trajectory, where the nuts sit in their gaps, the linear terms miss issue 24's 0.25 urad on the
    tied truth and the quadratic ones meet it."""
    scenario, linear, quadratic, inputs, curves = table1_design

    def rms(space):
        space = dataclasses.replace(space, breakaway_force=force)
        return _rms_urad(forward(scenario.values, inputs, space=space).angles[0] - curves[force])

    # issue 24's goal per angle; measured 0.08 / 0.06 / 0.01 urad (bench_form_error, both forces)
    assert np.all(rms(quadratic) <= 0.25), rms(quadratic)
    # the same bound fails with the linear terms: measured 0.16 / 0.58 / 0.13 urad
    assert np.any(rms(linear) > 0.25), rms(linear)
