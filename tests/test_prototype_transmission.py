"""Actuator transmission of the virtual prototype: the play operator, the nut offset law,
point classes, and what clearance does to the mechanism along a trajectory."""

import dataclasses

import numpy as np
import pytest

from flexcal.geometry.params import reference_mechanism
from flexcal.validation.prototype.mechanism import build_prototype, simulate
from flexcal.validation.prototype.segments import analytic_provider
from flexcal.validation.prototype.transmission import (ActuatorTransmission, nut_offset, play_operator, point_class)

PROVIDER = analytic_provider()
MECH = reference_mechanism()


def test_play_operator_holds_inside_the_band_and_follows_behind_outside():
    band = 1.0
    targets = [0.0, 0.5, 2.0, 3.0, 2.5, 1.5, 0.0, -0.5]
    state, path = None, []
    for t in targets:
        state = play_operator(state, t, band)
        path.append(float(state))
    # start: no history -> target; 0.5 within the band -> stays; 2, 3 -> 1 behind; back down:
    # holds while within 1, then follows 1 above
    assert path == [0.0, 0.0, 1.0, 2.0, 2.0, 2.0, 1.0, 0.5]


def test_play_operator_is_rate_independent():
    fine = np.linspace(0, 5, 501)
    coarse = np.array([0.0, 5.0])
    run = lambda seq: [s := None] and [s := play_operator(s, t, 0.7) for t in seq][-1]
    assert run(fine) == pytest.approx(run(coarse))  # only the extreme matters, not the path speed


def test_zero_breakaway_is_the_memoryless_law():
    rng = np.random.default_rng(0)
    tension = rng.normal(scale=300, size=(50, 3))
    stiffness = rng.uniform(1e6, 3e6, size=(50, 3))
    offset = rng.uniform(0, 1e-4, size=(50, 3))
    mu, cl = np.array([0.83, 0.87, 0.93]), np.array([0.42e-3, 0.25e-3, 0.1e-3])
    previous = rng.uniform(0, 1e-4, size=(50, 3))  # any history
    got = nut_offset(previous, tension, stiffness, offset, mu, cl, np.zeros(3))
    expected = np.clip(mu * (offset + tension / stiffness), 0, cl)  # clip(mu * release, 0, CL)
    assert np.array_equal(got, expected)


def test_breakaway_band_leaves_memory():
    k, breakaway = 2e6, 10.0  # band F_b / k = 5 um
    up = nut_offset(None, 100.0, k, 0.0, 1.0, 1e-3, breakaway)  # no history: the rest offset N/k
    assert up == pytest.approx(50e-6)
    # re-evaluated at its own equilibrium (tension released, N = 0): the nut stays
    assert nut_offset(up, 0.0, k, up, 1.0, 1e-3, breakaway) == pytest.approx(up)
    # the load drops so that the rest offset is 48 um (within the band): held by friction
    assert nut_offset(up, -k * 2e-6, k, up, 1.0, 1e-3, breakaway) == pytest.approx(up)
    # rest offset 10 um: the nut follows one band (5 um) behind, at 15 um
    assert nut_offset(up, -k * 40e-6, k, up, 1.0, 1e-3, breakaway) == pytest.approx(15e-6)


def test_compression_keeps_the_nut_on_its_flank():
    got = nut_offset(np.array([0.0, 30e-6]), np.array([-500.0, -500.0]), 2e6, np.zeros(2), 0.9, 0.4e-3, 2.0)
    assert np.array_equal(got, [0.0, 0.0])


def test_point_classes():
    tension = np.array([[-10, -20, -5], [-10, -20, 5], [-10, 20, -5], [-10, -20, -5]])
    offsets = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 1e-6, 0]])
    assert list(point_class(tension, offsets)) == ["S1", "S3", "S3", "S2"]


def test_bad_transmission_values_are_refused():
    with pytest.raises(ValueError, match="clearance"):
        ActuatorTransmission(clearance=-1e-4)
    with pytest.raises(ValueError, match="hysteresis"):
        ActuatorTransmission(hysteresis=1.2)
    with pytest.raises(ValueError, match="breakaway"):
        ActuatorTransmission(breakaway_force=-1.0)


def _leg(amplitude, n, actuator):
    s = np.arange(1, n + 1) / n
    wave = np.where(s <= 0.25, 4 * s, np.where(s <= 0.75, 2 - 4 * s, 4 * s - 4))
    out = np.zeros((n + 1, 3))
    out[1:, actuator] = amplitude * wave
    return out


def test_no_lost_motion_under_steady_compression():
    """D1 stays compressed by the weight over its whole sweep: its clearance changes nothing."""
    inputs = _leg(0.6e-3, 16, 0)  # at the full 0.98 mm D1 would reach tension (S2 near -A)
    plain = simulate(build_prototype(MECH, [ActuatorTransmission()] * 3, PROVIDER), inputs)
    loose = [ActuatorTransmission(clearance=0.4e-3, hysteresis=0.9)] + [ActuatorTransmission()] * 2
    run = simulate(build_prototype(MECH, loose, PROVIDER), inputs)
    assert np.all(run.axial_loads[:, 3] < 0)  # D1 compressed throughout
    assert np.all(run.nut_offsets[:, 0] == 0.0)
    assert np.allclose(run.angles, plain.angles, rtol=0, atol=1e-13)  # same physics path: round-off only


def test_lost_motion_and_hysteresis_when_the_load_changes_sign():
    """Weightless frame, D3 pushed then pulled: in tension its nut slides into the play."""
    weightless = dataclasses.replace(MECH, payload_mass=0.0)
    inputs = _leg(0.5e-3, 24, 2)
    tight = simulate(build_prototype(weightless, [ActuatorTransmission()] * 3, PROVIDER), inputs)
    # mu = 0.5: the nut takes up half of the ~0.5 mm release, inside the 0.4 mm play (unclipped)
    gap = [ActuatorTransmission()] * 2 + [ActuatorTransmission(clearance=0.4e-3, hysteresis=0.5,
                                                               breakaway_force=20.0)]
    run = simulate(build_prototype(weightless, gap, PROVIDER), inputs)
    pushing = inputs[:, 2] > 0
    pulling = inputs[:, 2] < 0
    # pushing compresses D3: the nut sits on its flank and nothing is lost
    assert np.all(tight.axial_loads[pushing, 5] < 0)
    assert np.all(run.nut_offsets[pushing, 2] == 0)
    # nut offset exactly 0: the same equilibrium problem, to round-off
    assert np.allclose(run.angles[pushing], tight.angles[pushing], rtol=0, atol=1e-12)
    # pulling: the nut takes up slack, theta_x lags the tight mechanism (lost motion)
    lost = np.abs(tight.angles[pulling, 0]) - np.abs(run.angles[pulling, 0])
    assert np.all(run.nut_offsets[pulling, 2] > 0)
    assert np.all(lost > 0)
    assert set(run.point_class[pulling]) == {"S2"}
    # breakaway memory: at equal commands the nut sits higher on the way back up than on the
    # way down (it lags the rest offset by the band both ways): a hysteresis loop
    command = inputs[:, 2]
    down = [i for i in range(1, len(command)) if command[i] < 0 and command[i] < command[i - 1]]
    up = [i for i in range(1, len(command)) if command[i] < 0 and command[i] > command[i - 1]]
    pairs = [(i, j) for i in down for j in up if np.isclose(command[i], command[j])]
    assert len(pairs) >= 3
    for i, j in pairs:
        assert run.nut_offsets[j, 2] > run.nut_offsets[i, 2]
        assert abs(run.angles[j, 0] - run.angles[i, 0]) > 1e-7  # visible in theta_x, > 0.1 urad
    # without breakaway the law is memoryless: no loop (to the 1e-12 m offset tolerance)
    memoryless = [ActuatorTransmission()] * 2 + [ActuatorTransmission(clearance=0.4e-3, hysteresis=0.5,
                                                                      breakaway_force=0.0)]
    free = simulate(build_prototype(weightless, memoryless, PROVIDER), inputs)
    for i, j in pairs:
        # the 1e-12 m offset tolerance (comment above), 10x
        assert free.nut_offsets[j, 2] == pytest.approx(free.nut_offsets[i, 2], abs=1e-11)
