"""Mode shapes, Craig-Bampton and the Newton check of the mount's buckling factor
(flexcal.validation.structure.{mode_shapes, craig_bampton, buckling_check})."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from flexcal.geometry.params import reference_mechanism
from flexcal.validation.prototype.mechanism import FRAME_BODY, NUT_BODIES, build_prototype
from flexcal.validation.prototype.segments import analytic_provider
from flexcal.validation.prototype.transmission import ActuatorTransmission
from flexcal.validation.structure.buckling_check import newton_buckling_scan
from flexcal.validation.structure.craig_bampton import craig_bampton
from flexcal.validation.structure.mode_shapes import mode_points, point_motion
from flexcal.validation.structure.mount import mount_buckling_factor, nominal_state, rigid_influence


@pytest.fixture(scope="module")
def mount():
    mechanism = reference_mechanism()
    prototype = build_prototype(mechanism, [ActuatorTransmission()] * 3, analytic_provider(mechanism.material))
    return prototype, nominal_state(prototype)


def _spring_chain(n=10, seed=1):
    """A chain of n masses on n - 1 springs plus a spring to ground at each end (SPD)."""
    rng = np.random.default_rng(seed)
    k = rng.uniform(1.0, 3.0, n + 1)
    K = np.diag(k[:-1] + k[1:]) - np.diag(k[1:-1], 1) - np.diag(k[1:-1], -1)
    M = np.diag(rng.uniform(0.5, 2.0, n))
    return K, M


def test_craig_bampton_keeps_every_mode_exactly_and_guyan_the_static_stiffness():
    K, M = _spring_chain()
    boundary = np.array([0, 9])
    interior = np.arange(1, 9)
    full = scipy.linalg.eigh(K, M, eigvals_only=True)
    every = craig_bampton(K, M, boundary, len(interior))
    # a change of basis: same eigenvalues to round-off
    np.testing.assert_allclose(scipy.linalg.eigh(every.stiffness, every.mass, eigvals_only=True), full, rtol=1e-10)
    guyan = craig_bampton(K, M, boundary, 0)
    schur = K[np.ix_(boundary, boundary)] - K[np.ix_(boundary, interior)] @ np.linalg.solve(
        K[np.ix_(interior, interior)], K[np.ix_(interior, boundary)])
    np.testing.assert_allclose(guyan.stiffness, schur, rtol=1e-12)  # 1e-12: the same Schur complement by two routes, round-off
    fixed = np.sqrt(scipy.linalg.eigh(K[np.ix_(interior, interior)], M[np.ix_(interior, interior)],
                                      eigvals_only=True)[:3]) / (2 * np.pi)
    np.testing.assert_allclose(craig_bampton(K, M, boundary, 3).fixed_interface_Hz, fixed, rtol=1e-12)  # 1e-12: the same fixed-interface eigenproblem solved twice, round-off
    # Rayleigh-Ritz: a reduced basis never lowers an eigenvalue, and more modes come closer
    two = scipy.linalg.eigh(craig_bampton(K, M, boundary, 2).stiffness, craig_bampton(K, M, boundary, 2).mass,
                            eigvals_only=True)
    g = scipy.linalg.eigh(guyan.stiffness, guyan.mass, eigvals_only=True)
    assert np.all(two >= full[:4] * (1 - 1e-12)) and two[0] - full[0] <= g[0] - full[0]  # 1e-12: Rayleigh-Ritz bound up to round-off


def test_point_motion_of_rigid_motions(mount):
    """A unit rigid translation along x moves every point on a body with six DOFs by e_x
    and a nut's points by e_x's component along the nut's axis; a unit rotation about z
    through O_C moves the payload box's corners by e_z x p (exact: linear maps)."""
    prototype, state = mount
    points, bodies, _ = mode_points(prototype, state.poses)
    r = rigid_influence(prototype, state.poses)
    shift = point_motion(prototype, state.poses, r[:, 0])
    six = np.array([prototype.assembly.body_selection[b].shape[1] == 6 for b in bodies])
    np.testing.assert_allclose(shift[six], np.tile([1.0, 0, 0], (six.sum(), 1)), atol=1e-12)  # 1e-12: an exact linear map, round-off
    for nut in NUT_BODIES:
        axis = state.poses[nut, :3, 0]
        np.testing.assert_allclose(shift[bodies == nut], np.tile(axis[0] * axis, ((bodies == nut).sum(), 1)), atol=1e-12)  # 1e-12: exact, round-off
    assert np.all(shift[np.array([prototype.assembly.body_selection[b].shape[1] == 0 for b in bodies])] == 0)
    turn = point_motion(prototype, state.poses, r[:, 5])
    box = bodies == FRAME_BODY
    np.testing.assert_allclose(turn[box], np.cross([0.0, 0.0, 1.0], points[box]), atol=1e-12)  # 1e-12: exact, round-off


def test_newton_scan_at_the_nominal_weight_reproduces_the_linearized_factor(mount):
    """mu(1) = 1 - 1 / s_cr when the tangent is linear in the weight factor between 0 and
    1 (K_T(1) = K_0 + dK, and s_cr makes K_0 + s_cr dK singular), so 1 / (1 - mu(1)) must
    be the linearized factor; the tangent's own nonlinearity over s in [0, 1] is
    ~1/s_cr^2 ~ 3e-4 of it (bound 1e-3)."""
    prototype, state = mount
    scan = newton_buckling_scan(prototype, (1.0,))
    factor = mount_buckling_factor(nominal_state(prototype, 0.0), state)
    assert 1.0 / (1.0 - scan["lowest_eigenvalue"][0]) == pytest.approx(factor, rel=1e-3)  # 1e-3: the docstring's bound on the tangent's nonlinearity (~3e-4)


@pytest.mark.slow
def test_newton_fails_where_the_lowest_eigenvalue_reaches_zero(mount):
    """Beyond the nonlinear limit load Newton has no equilibrium to converge to: it must
    fail within a few % of where mu extrapolates to zero (measured: converged to 95.6,
    failed at 96.25, mu -> 0 at 96.5)."""
    prototype, _ = mount
    scan = newton_buckling_scan(prototype, (1.0, 80.0, 90.0, 100.0), bisections=3)
    assert scan["newton_failed_at"] is not None
    # 3 %: the linear extrapolation of mu over the last 10 % of the load, mu is concave there
    assert scan["newton_failed_at"] == pytest.approx(scan["zero_crossing"], rel=0.03)
    assert scan["newton_converged_to"] > 1.5 * mount_buckling_factor(nominal_state(prototype, 0.0),  # 1.5: the nonlinear path stiffens: Newton converged to 95.6 vs the linearized 55.5
                                                                     nominal_state(prototype))
