"""Forward model (Eq. 2-8): linear limit against an independent 12x12 assembly, the small-input
linearization, batched == looped, engines and the plain reference agree, invariants, errors."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flexcal.geometry.frames import chain_rotation
from flexcal.geometry.params import FlexureChain, reference_mechanism
from flexcal.model import kernel
from flexcal.model.assembly import mechanism_matrices, payload_wrench
from flexcal.model.chain import chain_stiffness_matrix
from flexcal.model.clearance import ConvergenceError
from flexcal.model.forward import forward
from flexcal.model.parameters import parameter_space
from flexcal.model.reference import reference_forward
from flexcal.model.trajectory import standard_trajectory

SPACE = parameter_space()
TRAJECTORY = standard_trajectory()
# forward converges to |du| <= 1e-13 m; the angles move by <= 3.3 rad/m of u (input_gain of the
# reference mechanism), so two converged answers may differ by ~2 * 3.3e-13 rad
ANGLE_TOL = 1e-12


def random_values(n, seed, **fixed):
    rng = np.random.default_rng(seed)
    values = SPACE.from_unit(rng.random((n, 45)))
    for name, value in fixed.items():
        values[:, SPACE.index(name)] = value
    return values


def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def independent_linear_pose(space, values, inputs):
    """Eq. 2-3 the long way: each chain's 12x12 stiffness (chain_stiffness_matrix), its ends
    mapped to the unknowns q = [X_C (6), axial A-end displacement of D1..D3 (3)], the
    actuators as springs to the nut positions; returns X_C (6,) for one parameter set."""
    mech = space.mechanism
    k_total, rhs = np.zeros((9, 9)), np.zeros(9)
    rhs[:6] = payload_wrench(mech)
    for i, placement in enumerate(mech.chains):
        w, a, l, t1, t2 = values[5 * i:5 * i + 5]
        point_a = np.array(placement.point_a, dtype=float)
        if not placement.is_driving:
            d, phi = values[30 + 2 * i], values[31 + 2 * i]
            rot0 = placement.rotation
            point_a = point_a + d * (np.cos(phi) * rot0[:, 1] + np.sin(phi) * rot0[:, 2])
        point_b = np.array(placement.point_b, dtype=float)
        ch = FlexureChain(length=float(np.linalg.norm(point_b - point_a)), hinge_length=l, width=w, fillet=a,
                          thickness_1=t1, thickness_2=t2, section=placement.chain.section,
                          connector_length=placement.chain.connector_length,
                          end_block_length=placement.chain.end_block_length)
        k12 = chain_stiffness_matrix(ch, mech.material)
        rot = chain_rotation(point_a, point_b, np.array(placement.roll_reference))
        to_b = np.zeros((6, 6))  # global twist at O_C -> B's twist in chain axes
        to_b[:3, :3] = rot.T
        to_b[:3, 3:] = -rot.T @ skew(point_b)
        to_b[3:, 3:] = rot.T
        mapping = np.zeros((12, 9))
        mapping[6:, :6] = to_b
        if placement.is_driving:
            mapping[0, 6 + i - 3] = 1.0  # the A end slides along the chain axis only
        k_total += mapping.T @ k12 @ mapping
    for k in range(3):
        stiffness = mech.actuator_stiffness
        k_total[6 + k, 6 + k] += stiffness
        rhs[6 + k] += stiffness * (inputs[k] + values[38 + 3 * k])
    return np.linalg.solve(k_total, rhs)[:6]


def test_linear_limit_equals_an_independent_assembly():
    values = random_values(3, 1)
    inputs = np.array([[0.4e-3, -0.3e-3, 0.2e-3], [0.0, 0.0, 0.0]])
    result = forward(values, inputs, parasitic=False, clearance=False)
    for c in range(3):
        for p in range(2):
            expected = independent_linear_pose(SPACE, values[c], inputs[p])
            # cond(K) ~ 1e3: the two assemblies agree to rounding, 1e-12 of the largest entry
            np.testing.assert_allclose(result.pose[c, p], expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def test_zero_clearance_and_parasitic_is_the_linear_model_exactly():
    values = random_values(4, 2, **{"D1.CL": 0.0, "D2.CL": 0.0, "D3.CL": 0.0})
    linear = forward(values, TRAJECTORY.inputs, parasitic=False, clearance=False)
    with_clearance_switch = forward(values, TRAJECTORY.inputs, parasitic=False, clearance=True)
    np.testing.assert_array_equal(with_clearance_switch.pose, linear.pose)
    m = mechanism_matrices(values, SPACE)
    u = np.zeros((4, TRAJECTORY.n_points, 6))
    u[..., 3:] = TRAJECTORY.inputs[None] + m.initial_position[:, None, :]
    expected = m.gravity_pose[:, None, :] + np.einsum("cij,cpj->cpi", m.input_gain, u)
    np.testing.assert_allclose(linear.pose, expected, rtol=0, atol=1e-15)  # same products, other order


def test_small_inputs_follow_the_linearization_to_second_order():
    # without gravity the parasitic term is purely quadratic in the pose: full - linear = O(x^2)
    mech = dataclasses.replace(reference_mechanism(), payload_mass=0.0)
    space = parameter_space(mech)
    direction = np.array([[0.8e-3, -0.5e-3, 0.6e-3]])
    scales = np.array([1.0, 0.5, 0.25, 0.125])
    gaps = []
    for s in scales:
        full = forward(space.nominal_full, s * direction, space=space).angles[0, 0]
        linear = forward(space.nominal_full, s * direction, space=space, parasitic=False, clearance=False).angles[0, 0]
        gaps.append(np.max(np.abs(full - linear)))
    slope = np.polyfit(np.log(scales), np.log(gaps), 1)[0]
    assert slope == pytest.approx(2.0, abs=0.02)  # the next term is O(x^4): 2 % of slope is ample
    zero = forward(space.nominal_full, np.zeros((1, 3)), space=space)
    assert np.all(zero.pose == 0.0) and np.all(zero.parasitic == 0.0)  # unloaded design pose


def test_offsets_and_dimension_errors_keep_the_unloaded_pose():
    mech = dataclasses.replace(reference_mechanism(), payload_mass=0.0)
    space = parameter_space(mech)
    values = space.from_unit(np.random.default_rng(3).random((5, 45)))
    values[:, [38, 41, 44]] = 0.0  # no initial positions: nothing moves the frame
    result = forward(values, np.zeros((1, 3)), space=space)
    assert np.max(np.abs(result.pose)) == 0.0  # chains are built to fit: no preload anywhere


@pytest.mark.parametrize("n_candidates, points", [(1, [0]), (3, [0, 7, 8, 30, 60]), (5, list(range(0, 77, 4)))])
def test_batched_equals_looped(n_candidates, points):
    values = random_values(n_candidates, 10 + n_candidates)
    inputs, directions = TRAJECTORY.inputs[points], TRAJECTORY.directions[points]
    batched = forward(values, inputs, directions)
    assert batched.pose.shape == (n_candidates, len(points), 6)
    for c in range(n_candidates):
        for j in range(len(points)):
            single = forward(values[c], inputs[j:j + 1], directions[j:j + 1])
            np.testing.assert_allclose(single.pose[0, 0], batched.pose[c, j], rtol=0, atol=ANGLE_TOL)
            np.testing.assert_array_equal(single.chain_states[0, 0], batched.chain_states[c, j])
            assert single.point_class[0, 0] == batched.point_class[c, j]


def test_engines_and_the_plain_reference_agree():
    values = random_values(12, 4)
    # the plain reference implements the directional reading; force_only is d = +1 of it
    numpy_result = forward(values, TRAJECTORY.inputs, engine="numpy", clearance_mode="directional")
    if kernel.available():
        compiled = forward(values, TRAJECTORY.inputs, engine="numba", clearance_mode="directional")
        np.testing.assert_allclose(compiled.pose, numpy_result.pose, rtol=0, atol=ANGLE_TOL)
        # 1 pm: the fixed point stops at |du| <= 1e-13 m
        np.testing.assert_allclose(compiled.clearance, numpy_result.clearance, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(compiled.chain_states, numpy_result.chain_states)
    threaded = forward(values, TRAJECTORY.inputs, n_threads=2, clearance_mode="directional")
    np.testing.assert_allclose(threaded.pose, numpy_result.pose, rtol=0, atol=ANGLE_TOL)
    m = mechanism_matrices(values[:2], SPACE)
    points = slice(0, 30)
    pose, clear = reference_forward(m, SPACE.mechanism, TRAJECTORY.inputs[points], TRAJECTORY.directions[points])
    np.testing.assert_allclose(pose, numpy_result.pose[:2, points], rtol=0, atol=ANGLE_TOL)
    np.testing.assert_allclose(clear, numpy_result.clearance[:2, points], rtol=0, atol=1e-12)  # 1 pm, >> rounding


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31), scale=st.floats(0.1, 1.5))
def test_eq7_holds_and_states_match_it(seed, scale):
    values = random_values(4, seed)
    rng = np.random.default_rng(seed)
    inputs = scale * rng.uniform(-1e-3, 1e-3, (12, 3))
    mu, limit = values[:, SPACE.indices("*.mu")][:, None, :], values[:, SPACE.indices("*.CL")][:, None, :]
    force_only = forward(values, inputs, clearance_mode="force_only")
    # force-only reading: d_i = +1, C = clip(mu fx, 0, CL) with fx = N(C_i = 0)/s
    np.testing.assert_allclose(force_only.clearance, np.clip(mu * force_only.release, 0.0, limit), rtol=0, atol=1e-12)
    result = forward(values, inputs, clearance_mode="directional")
    y = result.directions[None] * result.clearance  # d_i C_i
    # Eq. 7 with ul = CL: d C = clip(mu fx, 0, CL), fx = d N(C_i = 0)/s (1e-12 m: the fixed point
    # tolerance 1e-13 m times the nut's gain on the load)
    np.testing.assert_allclose(y, np.clip(mu * result.release, 0.0, limit), rtol=0, atol=1e-12)
    engaged = result.chain_states == 0
    assert np.all(np.abs(result.clearance[engaged]) <= 1e-12)  # 1 pm: the fixed-point tolerance, as above
    far = result.chain_states == 2
    # as above
    assert np.allclose(np.abs(result.clearance[far]), np.broadcast_to(limit, y.shape)[far], rtol=0, atol=1e-12)
    s2 = np.any(result.chain_states > 0, axis=-1)
    assert np.all((result.point_class == 2) == s2)
    compressed = np.all(result.axial_loads[..., 3:] < 0, axis=-1)
    assert np.all(result.point_class[~s2] == np.where(compressed[~s2], 1, 3))


def test_force_only_mode_ignores_directions():
    values = random_values(3, 7)
    plus = forward(values, TRAJECTORY.inputs, np.ones((77, 3)), clearance_mode="force_only")
    minus = forward(values, TRAJECTORY.inputs, -np.ones((77, 3)), clearance_mode="force_only")
    np.testing.assert_array_equal(plus.pose, minus.pose)
    assert np.all(plus.clearance >= 0)  # only tension opens the gap, towards B


def test_gravity_compresses_d1_d2_at_the_design_pose():
    result = forward(SPACE.nominal_full, np.zeros((1, 3)))
    loads = result.axial_loads[0, 0]
    assert loads[3] < 0 and loads[4] < 0  # docs/conventions.md: the weight compresses D1 and D2
    assert abs(np.sum(loads[:3])) > 0 and np.all(np.abs(result.pose[0, 0, 3:]) < 2e-4)  # sag < 200 urad


def test_a_point_out_of_range_raises_a_named_error_not_nan():
    inputs = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.0, 0.0]])  # 300 mm: far outside
    for engine in ("numpy", "numba") if kernel.available() else ("numpy",):
        with pytest.raises(ConvergenceError) as info:
            forward(random_values(2, 5), inputs, engine=engine)
        assert info.value.point == 1 and "point 1" in str(info.value) and "candidate" in str(info.value)
    with pytest.raises(ValueError, match="point 1"):
        forward(SPACE.nominal_full, np.array([[0, 0, 0], [np.nan, 0, 0]]))
    bad = random_values(3, 6)
    bad[2, SPACE.index("D2.t1")] = -1e-3
    with pytest.raises(ValueError, match="candidate 2: parameter D2.t1"):
        forward(bad, np.zeros((1, 3)))


def test_every_stiffness_of_random_candidates_is_spd():
    m = mechanism_matrices(random_values(50, 8), SPACE)
    for matrices in (m.chain_stiffness.reshape(-1, 6, 6), m.frame_stiffness):
        scale = np.abs(matrices).max(axis=(1, 2), keepdims=True)
        # symmetric by construction: round-off only
        np.testing.assert_allclose(matrices, np.swapaxes(matrices, 1, 2), rtol=0, atol=1e-12 * scale.max())
        assert np.all(np.linalg.eigvalsh(matrices / scale) > 0)
    np.testing.assert_allclose(m.coupling, np.swapaxes(m.coupling, 1, 2), rtol=1e-9)  # m_ij = g_i^T K^-1 g_j
    assert np.all(m.nut_stiffness > 0) and np.all(m.parasitic_coefficient > 0)


def test_compiled_assembly_equals_numpy(monkeypatch):
    pytest.importorskip("numba")
    values = random_values(40, 12)  # >= COMPILED_MIN_CANDIDATES: compiled linear algebra
    compiled = mechanism_matrices(values, SPACE)
    monkeypatch.setattr(kernel, "available", lambda: False)
    # Cholesky vs LU and another summation order: cond(K_CC) ~ 300 times 1e-16
    _assert_fields_close(compiled, mechanism_matrices(values, SPACE), 1e-12)


def _assert_fields_close(got, want, relative: float) -> None:
    """Every field of two ``MechanismMatrices`` within ``relative`` of the field's largest entry."""
    for field in dataclasses.fields(want):
        a, b = getattr(got, field.name), getattr(want, field.name)
        # relative: the caller's, with its reason there
        np.testing.assert_allclose(a, b, rtol=0, atol=relative * np.abs(b).max(), err_msg=field.name)


@pytest.mark.skipif(not kernel.available(), reason="the compiled engine needs numba")
@pytest.mark.parametrize("model", ["second-order", "consistent with the play state"])
def test_the_compiled_engine_gives_the_same_bits_on_any_thread_count(model):
    """``forward(..., n_threads=2)`` sets the whole batch up as one thread does and solves each
    candidate in its own loop on numba's threads: the same bits as one thread, on a Jacobian's
    batch (a base candidate and each source moved, many chains alike) and on 150 random
    candidates (where the setup was split over threads before session 32, moving the last bits)."""
    space = dataclasses.replace(SPACE, second_order=True)
    if model != "second-order":
        space = dataclasses.replace(space, breakaway_force=2.0, chain_shortening=tuple(np.zeros(216)))
    base = random_values(1, 32)[0]
    jacobian = np.repeat(base[None], 46, axis=0)
    jacobian[np.arange(1, 46), np.arange(45)] *= 1.0 + 1e-6
    for values in (jacobian, random_values(150, 33)):
        one = forward(values, TRAJECTORY.inputs, space=space)
        two = forward(values, TRAJECTORY.inputs, space=space, n_threads=2)
        for field in ("pose", "axial_loads", "clearance", "chain_states"):
            np.testing.assert_array_equal(getattr(two, field), getattr(one, field))


def _consistent(space):
    return dataclasses.replace(space, second_order=True, breakaway_force=2.0, chain_shortening=tuple(np.zeros(216)))


@pytest.mark.skipif(not kernel.available(), reason="the compiled engine needs numba")
def test_a_consistent_candidate_alone_gives_the_bits_it_gives_in_a_batch():
    """The consistent model's set-up runs compiled at every batch size (``mechanism_matrices``):
    a candidate evaluated alone, as a least-squares residual is, gives the same bits as in a
    Jacobian's batch of 46 (before, the single candidate's set-up ran numpy's formulas and the
    batch's the compiled ones, 1e-18 rad apart)."""
    space = _consistent(SPACE)
    base = random_values(1, 34)[0]
    jacobian = np.repeat(base[None], 46, axis=0)
    jacobian[np.arange(1, 46), np.arange(45)] *= 1.0 - 1e-6
    alone = forward(base, TRAJECTORY.inputs, space=space)
    batch = forward(jacobian, TRAJECTORY.inputs, space=space)
    for field in ("pose", "axial_loads", "clearance", "chain_states"):
        np.testing.assert_array_equal(getattr(alone, field)[0], getattr(batch, field)[0])


@pytest.mark.skipif(not kernel.available(), reason="the compiled engine needs numba")
def test_the_consistent_set_up_of_one_candidate_equals_numpys(monkeypatch):
    """The consistent model's compiled set-up of one candidate (one kernel pass for the chains'
    entries and the shortening's elements, the compiled frame algebra) against the numpy route
    (``chain_compliance_entries``, the dense forms, numpy's frame algebra)."""
    space = _consistent(SPACE)
    values = random_values(1, 35)
    compiled = mechanism_matrices(values, space)
    monkeypatch.setattr(kernel, "available", lambda: False)
    # 1e-10 of the field's largest entry: test_compiled_assembly_equals_numpy's 1e-12 (Cholesky
    # vs LU, cond(K_CC) ~ 300 times 1e-16) and the dense load form T's 4e-12 of its largest
    # entry (test_shortening_fast: K (C1 K C1 - C2) K subtracts terms ~1e2 x T); a zero field exactly
    _assert_fields_close(compiled, mechanism_matrices(values, space), 1e-10)
