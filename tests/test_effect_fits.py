"""Each model term describes its own injector's physics (issue #7, key check): the
prototype (analytic segments, nominal scenario, standard trajectory) with and without one
injected effect; only that term's parameters are fitted (scipy least_squares) to the
difference, with TermData from the no-effect run's angles and the analytic model's
finite-difference input Jacobian. Measured: the fraction of the signature's RMS the fit
removes, 1 - |residual| / |signature| (docs/effects.md has the table)."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from flexcal.validation.effects.library import EFFECT_IDS, OUT_OF_LIBRARY_IDS, make_injector, model_term
from flexcal.validation.effects.magnitude import estimate_magnitude
from flexcal.validation.effects.terms import build_term_data
from flexcal.validation.prototype.scenario import load_scenario
from flexcal.validation.prototype.segments import analytic_provider
from flexcal.validation.prototype.truth import make_truth

MAGNITUDE_URAD = 10.0
SEED = 1
# Terms whose injector differs only by its "richer" parts (second harmonic, load-dependent
# friction, thermal lag, sensor rotation vs. linear matrix, per-chain stiffening): measured
# 0.79-1.00 of the RMS removed at seed 1, so 0.7 (the "most of it") has >= 0.09 margin.
WELL_DESCRIBED = ("drift", "sensor_crosstalk", "sensor_scale", "lead_error", "friction_hysteresis",
                  "coupling_windup", "large_deflection", "thermal")
FAST = ("lead_error", "friction_hysteresis", "coupling_windup", "thermal", "creep", "sensor_crosstalk")
# Terms with a fitted place or time constant (nonlinear, fitted from the diagnosis's starts):
# step_loss (a one-move ramp at a fitted path fraction; measured 0.999 at seed 1, 0.997-0.999
# at seeds 1-5, the rest is the transmission's play and friction) and creep (one free time
# constant against the injector's two; 0.980 at seed 1, 0.970-0.982 at seeds 1-5). Bound 0.9:
# ~0.08-0.1 under the measured values; the former fixed-shape terms reached 0.79 and 0.81.
FITTED_SHAPE = {"step_loss": 0.9, "creep": 0.9}
# gravity_sag is only partly described (Hertz contact stiffness, solved at each point's own loads,
# against load polynomials of the *model's* loads; 0.67 at seed 1, 0.50-0.67 at seeds 1-5;
# 0.53 at seed 1 while the injector read the previous point's loads): bound ~0.1 under the lowest.
# sensor_settling: a first-order lag with a fitted time constant (0.997-0.999 at seeds 1-3):
# bound 0.9 as for the other fitted shapes. air_turbulence: an AR(1) series that the term's
# slow cosines (2..8 per trajectory) describe only in part (0.195 / 0.175 / 0.454 at seeds
# 1-3; the rest is its fast share, indistinguishable from noise): bound 0.1, under the lowest.
PARTLY_DESCRIBED = {"gravity_sag": 0.4, **FITTED_SHAPE, "sensor_settling": 0.9, "air_turbulence": 0.1}


@pytest.fixture(scope="module")
def nominal():
    scenario = load_scenario("nominal")
    base = make_truth(scenario, analytic_provider()).measurement
    data = build_term_data(scenario.values, base.inputs, time=base.time, leg=base.leg, extras=base.extras,
                           model_angles=base.angles)
    return scenario, base, data


def _signature(nominal, effect):
    scenario, base, _ = nominal
    return make_truth(scenario, analytic_provider(), effects=(effect,)).measurement.angles - base.angles


def _removed(nominal, effect_id, signature):
    term = model_term(effect_id)
    data = nominal[2]

    def residual(p):  # in urad: least_squares' default tolerances are absolute on the gradient
        return (term.evaluate(p * term.scale, data) - signature).ravel() * 1e6

    # the diagnosis's starts (diagnosis.which.fit_terms): zero, +-1 scale and two seeded draws;
    # a linear term reaches the same optimum from each
    k = term.n_params
    starts = [np.zeros(k), np.ones(k), -np.ones(k), *np.random.default_rng(0).normal(size=(2, k))]
    fit = min((least_squares(residual, s0) for s0 in starts), key=lambda f: f.cost)
    return 1.0 - np.linalg.norm(fit.fun) / np.linalg.norm(signature.ravel() * 1e6)


def _check(nominal, effect_id):
    effect = make_injector(effect_id, MAGNITUDE_URAD, SEED)
    signature = _signature(nominal, effect)
    achieved = np.sqrt(np.mean(signature**2)) * 1e6
    # the closed-form magnitude mapping is linearized on the nominal model: factor 2 (issue #7)
    assert 0.5 * MAGNITUDE_URAD < achieved < 2.0 * MAGNITUDE_URAD, achieved
    removed = _removed(nominal, effect_id, signature)
    bound = 0.7 if effect_id in WELL_DESCRIBED else PARTLY_DESCRIBED[effect_id]
    assert removed >= bound, (effect_id, removed)
    return achieved, removed


@pytest.mark.parametrize("effect_id", FAST)
def test_term_removes_most_of_its_injectors_signature(nominal, effect_id):
    _check(nominal, effect_id)


@pytest.mark.parametrize("effect_id", [e for e in EFFECT_IDS if e not in FAST])
def test_term_fits_the_other_injectors(nominal, effect_id):
    _check(nominal, effect_id)


@pytest.mark.parametrize("effect_id", OUT_OF_LIBRARY_IDS)
def test_out_of_library_effect_has_the_asked_magnitude(nominal, effect_id):
    effect = make_injector(effect_id, MAGNITUDE_URAD, SEED)
    achieved = np.sqrt(np.mean(_signature(nominal, effect) ** 2)) * 1e6
    # the linearized mapping's factor 2 (issue #7), as in _check
    assert 0.5 * MAGNITUDE_URAD < achieved < 2.0 * MAGNITUDE_URAD, achieved
    # make_injector rescales until within 1 % (effect_library.py); was rel=0.05
    assert estimate_magnitude(effect) * 1e6 == pytest.approx(MAGNITUDE_URAD, rel=0.01)
