"""Stress over the workspace (flexcal.validation.structure.workspace): corners reached on
the prototype, where a peak stress sits, the bisected stroke limit. Beam-theory segments
(seconds per test on a quiet machine)."""

from __future__ import annotations

import numpy as np
import pytest

from flexcal.geometry.params import reference_mechanism
from flexcal.validation.prototype.mechanism import build_prototype
from flexcal.validation.prototype.segments import analytic_provider
from flexcal.validation.prototype.transmission import ActuatorTransmission
from flexcal.validation.structure.fem_segments import FemSegments, mirror_map
from flexcal.validation.structure.mount import nominal_state
from flexcal.validation.structure.stress import chain_leaf_stresses, chain_peak_stress_beam
from flexcal.validation.structure.workspace import (ANGLE_TOL, commands_for_angles, frame_angles, locate, stress_at,
                                                    stroke_limit, workspace_corners)


@pytest.fixture(scope="module")
def prototype():
    mechanism = reference_mechanism()
    return build_prototype(mechanism, [ActuatorTransmission()] * 3, analytic_provider(mechanism.material))


def test_corners_are_the_eight_sign_combinations():
    corners = workspace_corners()
    assert corners.shape == (8, 3)
    assert len({tuple(np.sign(c)) for c in corners}) == 8
    np.testing.assert_array_equal(np.abs(corners), np.tile([1e-3, 5e-3, 3e-3], (8, 1)))


def test_corner_commands_put_the_prototype_at_the_corner(prototype):
    """The prototype, solved afresh at the returned commands, sits at the zero-command
    angles plus the target (to ANGLE_TOL; a fresh Newton from the design pose converges
    to ~1e-12 rad, far below it)."""
    target = workspace_corners()[[0, 7]]
    commands, _ = commands_for_angles(prototype, target)
    theta0 = frame_angles(nominal_state(prototype))
    for x, t in zip(commands, target):
        reached = frame_angles(nominal_state(prototype, commands=x)) - theta0
        np.testing.assert_allclose(reached, t, rtol=0, atol=2 * ANGLE_TOL)  # 2 x ANGLE_TOL: the corner search stops within ANGLE_TOL, the fresh Newton adds its own
    # the corners need more than the trajectory's ~1 mm strokes (all three at once)
    assert np.abs(commands).max() > 2e-3


def test_locate_names_the_piece():
    chain = reference_mechanism().chains[0].chain
    pieces = chain.segments()
    kind, a, b = pieces[1]  # the first leaf
    assert locate(chain, 0.5 * (a + b)) == "leaf 1 (thin part)"
    assert locate(chain, a + 0.5 * chain.fillet) == "leaf 1 (A fillet)"
    assert locate(chain, b - 0.5 * chain.fillet) == "leaf 1 (B fillet)"
    kind, a, b = pieces[-2]  # the last leaf is the fourth
    assert locate(chain, 0.5 * (a + b)) == "leaf 4 (thin part)"
    assert locate(chain, 0.5 * chain.length) == "strut"
    assert locate(chain, 0.0) == "block"


def test_beam_location_is_the_largest_of_the_leaf_sections(prototype):
    state = nominal_state(prototype, commands=np.array([0.8e-3, 0.0, 0.0]))
    values, labels = chain_leaf_stresses(prototype, state.segment_gradient)
    at = stress_at(prototype, state)
    np.testing.assert_array_equal(at.beam, chain_peak_stress_beam(prototype, state.segment_gradient))
    for c in range(6):
        assert at.beam_where[c] == labels[c][int(np.argmax(values[c]))]
        assert at.beam_where[c].startswith("leaf ")


def test_fem_peak_of_a_mirrored_slice_is_turned_back_into_place():
    """A fake canonical segment whose only stressed node answers to one DOF: for the
    mirrored slice the node is reported at (L - x, -y, z) of the chain."""
    chain = reference_mechanism().chains[0].chain
    fem = FemSegments()
    nodes = np.array([[0.010, 0.002, 0.003], [0.020, -0.001, 0.004]])
    unit = np.zeros((12, 2, 6), np.float32)
    unit[7, 1, 0] = 1e9  # end node's u_y moves node 1's sigma_xx
    L = chain.length
    fem._memo[(chain, L - 0.035, L)] = ({"unit_stress": unit, "nodes": nodes}, True)
    motion = np.zeros(12)
    k = int(np.argmax(np.abs(mirror_map()[:, 7])))  # the DOF of the mirrored slice that drives canonical DOF 7
    motion[k] = 1e-3
    value, where = fem.peak_von_mises_at(chain, L - 0.035, L, motion)
    assert value == pytest.approx(1e6, rel=1e-6)  # float32 of 1e9 x 1e-3
    np.testing.assert_allclose(where, [L - 0.020, 0.001, 0.004], rtol=0, atol=1e-15)  # 1e-15 m: the mirror map is exact coordinate arithmetic, round-off


def test_stroke_limit_bisects_to_the_limit(prototype):
    """With a peak that grows linearly with actuator 2's command from its nominal value
    (p = p0 + c |x_2|), the stroke is (limit - p0) / c to the bisection's tolerance; a
    limit below p0 gives 0, one out of reach inf."""
    p0, c = 10e6, 400e9  # [Pa], [Pa/m]

    def peak(state):
        return p0 + c * abs(state.commands[1])

    stroke = stroke_limit(prototype, 1, -1.0, 335e6, peak, rel_tol=1e-3)
    assert stroke == pytest.approx((335e6 - p0) / c, rel=1e-3)  # 1e-3: the bisection's rel_tol
    assert stroke_limit(prototype, 1, 1.0, 5e6, peak) == 0.0
    assert stroke_limit(prototype, 1, 1.0, 1e12, peak, max_stroke=2e-3) == float("inf")


def test_fem_figures_only_for_the_chains_asked(prototype):
    """A FEM source asked for chains 3-5 only: those get its figure and place (the largest
    over their segments), the others NaN and no place; the beam figures stay whole."""
    class Fake:
        def peak_von_mises_at(self, chain, x_start, x_end, motion):
            return 1e6 * (1.0 + x_start), np.array([0.5 * (x_start + x_end), 0.0, 0.0])

    state = nominal_state(prototype)
    at = stress_at(prototype, state, Fake(), chains=(3, 4, 5))
    assert np.all(np.isnan(at.fem[:3])) and at.fem_where[:3] == ("", "", "")
    np.testing.assert_allclose(at.fem[3:], 1e6 * (1.0 + prototype.section_x[3:, 4]))
    assert all(w.startswith("segment 5, ") for w in at.fem_where[3:])
    assert np.all(np.isfinite(at.beam))
