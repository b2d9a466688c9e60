"""The virtual prototype's mechanism: linear limit against an independent linear solve,
equilibrium of the whole, Newton on the standard trajectory, effects, determinism."""

import dataclasses

import numpy as np
import pytest

from flexcal.geometry.params import reference_mechanism
from flexcal.validation.prototype.mechanism import build_prototype, simulate
from flexcal.validation.prototype.equilibrium import SolverSettings
from flexcal.validation.prototype.segments import analytic_provider
from flexcal.validation.prototype.transmission import ActuatorTransmission

PROVIDER = analytic_provider()
MECH = reference_mechanism()
WEIGHTLESS = dataclasses.replace(MECH, payload_mass=0.0)
RIGID_NUTS = [ActuatorTransmission(clearance=0.0)] * 3


def _standard_inputs(mech):
    try:
        from flexcal.model.trajectory import standard_trajectory
    except ImportError:  # model not there: a plain sweep with the reference amplitudes
        amplitudes = np.array([0.98e-3, 0.98e-3, 0.64e-3])
        inputs = [np.zeros(3)]
        for k, n in enumerate((28, 28, 20)):
            s = np.arange(1, n + 1) / n
            wave = np.where(s <= 0.25, 4 * s, np.where(s <= 0.75, 2 - 4 * s, 4 * s - 4))
            for v in amplitudes[k] * wave:
                inputs.append(np.eye(3)[k] * v)
        return np.array(inputs)
    return standard_trajectory(mech).inputs


def _linear_response(mech, transmissions, inputs):
    """Independent linear model: the provider's 12 x 12 segments assembled per chain in
    world coordinates, node B tied to the frame twist at O_C, nuts on springs, the weight
    at the centre of gravity; solved for each input row. Returns poses (n, 6) [m, rad]."""
    from flexcal.validation.prototype.segments import section_nodes

    n_dof = 6 + 6 * 24 + 3
    k_glob = np.zeros((n_dof, n_dof))
    f_const = np.zeros(n_dof)
    f_anchor = np.zeros((n_dof, 3))  # right-hand side per unit anchor displacement
    for c, placement in enumerate(mech.chains):
        rot, x = placement.rotation, section_nodes(placement.chain)
        p_b = np.asarray(placement.point_b)
        # map global unknowns -> the 36 world-frame node DOFs of this chain -> local frame
        node_map = np.zeros((36, n_dof))
        if placement.is_driving:
            node_map[0:3, 6 + 144 + (c - 3)] = rot[:, 0]  # the nut slides along the axis
        for k in range(4):
            start = 6 + 6 * (4 * c + k)
            node_map[6 * (k + 1):6 * (k + 2), start:start + 6] = np.eye(6)
        skew_b = np.array([[0, -p_b[2], p_b[1]], [p_b[2], 0, -p_b[0]], [-p_b[1], p_b[0], 0]])
        node_map[30:33, 0:3] = np.eye(3)
        node_map[30:33, 3:6] = -skew_b  # u_B = u_C + theta x p_B
        node_map[33:36, 3:6] = np.eye(3)
        to_local = np.kron(np.eye(12), rot.T)  # world (u, theta) per node -> chain frame
        k_chain = np.zeros((36, 36))
        for s in range(5):
            k_chain[6 * s:6 * s + 12, 6 * s:6 * s + 12] += PROVIDER(placement.chain, x[s], x[s + 1])
        m = to_local @ node_map
        k_glob += m.T @ k_chain @ m
    for i, t in enumerate(transmissions):
        dof = 6 + 144 + i
        k_glob[dof, dof] += mech.actuator_stiffness
        f_anchor[dof, i] = mech.actuator_stiffness
    weight = mech.payload_mass * np.asarray(mech.gravity)
    f_const[:3] = weight
    f_const[3:6] = np.cross(np.asarray(mech.centre_of_gravity), weight)
    x0 = np.array([t.initial_position for t in transmissions])
    rhs = f_const[:, None] + f_anchor @ (np.asarray(inputs) + x0).T
    return np.linalg.solve(k_glob, rhs)[:6].T


def test_small_motions_match_an_independent_linear_solve():
    h = 1e-6
    steps = np.array([[h, 0, 0], [0, h, 0], [0, 0, h], [h, -h, h]])
    inputs = np.concatenate([np.zeros((1, 3)), steps, -steps])
    proto = build_prototype(WEIGHTLESS, RIGID_NUTS, PROVIDER,
                            settings=SolverSettings(force_tolerance=3e-6, moment_tolerance=1e-6))
    run = simulate(proto, inputs)
    linear = _linear_response(WEIGHTLESS, RIGID_NUTS, steps)
    assert np.all(run.pose[0] == 0.0)  # no load, no input: the design pose exactly
    odd = 0.5 * (run.pose[1:5] - run.pose[5:9])  # +h and -h: the quadratic terms cancel
    # what is left of the nonlinearity is cubic, ~(1e-5 rad)^2 = 1e-10 relative; the residual
    # tolerance (3e-6 N over the tripod's ~1e8 N/m at O_C) allows ~3e-14 m, ~1e-6 of the
    # ~2.5e-8 m translations (measured 7e-7): 1e-5 of the largest component bounds both
    for part in (slice(0, 3), slice(3, 6)):
        # bound from the comment above
        assert np.allclose(odd[:, part], linear[:, part], rtol=0, atol=1e-5 * np.max(np.abs(linear[:, part])))
    print("odd part vs linear, relative:", [np.max(np.abs(odd[:, p] - linear[:, p])) / np.max(np.abs(linear[:, p]))
                                            for p in (slice(0, 3), slice(3, 6))])
    # the even part is the geometric nonlinearity: second order, ~ (1e-5)^1 of the response
    even = 0.5 * (run.pose[1:5] + run.pose[5:9])
    # second order: ~1e-5 of the response (comment above), 10x margin
    assert np.max(np.abs(even[:, 3:])) < 1e-4 * np.max(np.abs(linear[:, 3:]))


def test_gravity_sag_is_close_to_linear_and_compresses_d1_d2():
    run = simulate(build_prototype(MECH, RIGID_NUTS, PROVIDER), np.zeros((1, 3)))
    linear = _linear_response(MECH, RIGID_NUTS, np.zeros((1, 3)))
    # the ~3 kN preload stiffens/softens the soft modes by N/L over the hinge stiffness and
    # rotations of ~1e-4 rad add second-order terms: measured 0.3-0.5 % on the angles
    assert np.allclose(run.angles[0], linear[0, 3:], rtol=0, atol=0.01 * np.max(np.abs(linear[0, 3:])))
    assert run.axial_loads[0, 3] < -1000 and run.axial_loads[0, 4] < -1000  # D1, D2 compressed (conventions)


def test_the_chains_carry_the_weight_to_the_supports():
    """Balance of the whole: the chains' forces and moments on their A ends add up to the weight."""
    from flexcal.validation.prototype.mechanism import _loads
    from flexcal.validation.effects.hooks import PointConditions
    from flexcal.validation.prototype.equilibrium import node_poses, solve_equilibrium

    proto = build_prototype(MECH, RIGID_NUTS, PROVIDER)
    command = np.array([0.5e-3, -0.3e-3, 0.4e-3])
    weight = MECH.payload_mass * np.asarray(MECH.gravity)
    conditions = PointConditions(segment_stiffness=proto.segment_stiffness,
                                 frame_forces=((weight, np.asarray(MECH.centre_of_gravity)),),
                                 actuator_stiffness=np.full(3, MECH.actuator_stiffness))
    poses, info = solve_equilibrium(proto.assembly, proto.initial_poses, proto.segment_stiffness.reshape(-1, 6, 6),
                                    _loads(proto, conditions, command), proto.settings)
    assert np.allclose(poses[0, :3, 3], simulate(proto, command[None]).pose[0, :3], atol=1e-12)  # same state
    nodes = node_poses(proto.assembly, poses)
    force, moment = np.zeros(3), np.zeros(3)
    for c in range(6):
        rot, p_a = nodes[6 * c, :3, :3], nodes[6 * c, :3, 3]
        g_a = info.segment_gradient[5 * c, :6]  # dU/d(node A) of the chain's first segment, A's frame
        f_c, m_c = rot @ -g_a[:3], rot @ -g_a[3:]  # what the chain does to its support
        force += f_c
        moment += np.cross(p_a, f_c) + m_c
    centre = poses[0, :3, 3] + poses[0, :3, :3] @ np.asarray(MECH.centre_of_gravity)
    # 25 free bodies each in balance to <= 1e-5 N and 1e-5 N m (SolverSettings), levers
    # <= 0.7 m: 1e-3 N and 1e-3 N m bound the sum of their errors
    assert np.allclose(force, weight, rtol=0, atol=1e-3)
    assert np.allclose(moment, np.cross(centre, weight), rtol=0, atol=1e-3)  # as above


def test_newton_converges_on_the_standard_trajectory_with_table1_transmissions():
    transmissions = [ActuatorTransmission(initial_position=-0.20e-3, clearance=0.42e-3, hysteresis=0.83),
                     ActuatorTransmission(initial_position=0.32e-3, clearance=0.25e-3, hysteresis=0.87),
                     ActuatorTransmission(initial_position=0.40e-3, clearance=0.10e-3, hysteresis=0.93)]
    proto = build_prototype(MECH, transmissions, PROVIDER)
    inputs = _standard_inputs(MECH)
    run = simulate(proto, inputs)
    assert run.angles.shape == (len(inputs), 3)
    assert np.all(run.force_residual <= proto.settings.force_tolerance)
    assert np.all(run.moment_residual <= proto.settings.moment_tolerance)
    assert np.all(run.newton_iterations < 10 * run.offset_iterations)  # no point needed a struggle
    assert np.all((run.nut_offsets >= 0) & (run.nut_offsets <= [t.clearance for t in transmissions]))
    print(f"77 points: {run.wall_time:.2f} s, Newton steps {run.newton_iterations.sum()}, "
          f"max residual {run.force_residual.max():.2g} N / {run.moment_residual.max():.2g} N m")


def test_same_inputs_give_identical_runs():
    proto = build_prototype(MECH, [ActuatorTransmission(clearance=0.1e-3, hysteresis=0.9)] * 3, PROVIDER)
    inputs = np.array([[0, 0, 0], [0.3e-3, 0, 0], [0, -0.2e-3, 0.1e-3], [0, 0, -0.4e-3]])
    a, b = simulate(proto, inputs), simulate(proto, inputs)
    for name in ("angles", "pose", "axial_loads", "nut_offsets", "newton_iterations"):
        assert np.array_equal(getattr(a, name), getattr(b, name))


@dataclasses.dataclass(frozen=True)
class ConstantScrewOffset:
    """A trivial effect: the screw of one actuator sits ``offset`` [m] further along."""

    actuator: int
    offset: float
    name: str = "constant_screw_offset"

    @property
    def parameters(self):
        return {"actuator": self.actuator, "offset_m": self.offset}

    def modify_screw_position(self, actuator, command, position, context):
        return position + (self.offset if actuator == self.actuator else 0.0)


@dataclasses.dataclass(frozen=True)
class SensorOffset:
    offset: tuple
    name: str = "sensor_offset"
    parameters: dict = dataclasses.field(default_factory=dict)

    def measure(self, angles, context):
        return angles + np.asarray(self.offset)


def test_an_effect_acts_inside_the_physics_and_is_recorded():
    inputs = np.array([[0, 0, 0], [0.2e-3, 0, 0], [0, 0, -0.2e-3]])
    plain = build_prototype(MECH, RIGID_NUTS, PROVIDER)
    shifted = build_prototype(MECH, [ActuatorTransmission(initial_position=50e-6)] + RIGID_NUTS[1:], PROVIDER)
    effect = ConstantScrewOffset(actuator=0, offset=50e-6)
    with_effect = simulate(plain, inputs, effects=[effect])
    reference = simulate(shifted, inputs)
    baseline = simulate(plain, inputs)
    # the effect is the same physics as a shifted initial position (to round-off of x + x0 + d)
    assert np.allclose(with_effect.axial_loads, reference.axial_loads, rtol=0, atol=1e-6)
    # same Newton path: only x + x0 + d rounds differently
    assert np.allclose(with_effect.angles, reference.angles, rtol=0, atol=1e-12)
    # and it changes the loads in the chains, not only the angles (50 um against ~1.6e6 N/m)
    assert np.min(np.abs(with_effect.axial_loads[:, 3] - baseline.axial_loads[:, 3])) > 10.0
    assert with_effect.provenance["effects"] == [{"name": "constant_screw_offset",
                                                   "parameters": {"actuator": 0, "offset_m": 50e-6}}]


def test_sensor_effects_change_only_the_measurement():
    inputs = np.array([[0, 0, 0], [0.2e-3, 0, 0]])
    proto = build_prototype(MECH, RIGID_NUTS, PROVIDER)
    base = simulate(proto, inputs)
    run = simulate(proto, inputs, effects=[SensorOffset(offset=(1e-6, 0.0, -2e-6))])
    assert np.array_equal(run.true_angles, base.true_angles)
    assert np.array_equal(run.axial_loads, base.axial_loads)
    # offset added to ~1e-3 rad angles: round-off (1 ulp = 2e-19 rad); rtol=0 (default 1e-5 hid it)
    assert np.allclose(run.angles - base.angles, [1e-6, 0.0, -2e-6], rtol=0, atol=1e-18)


def test_bad_inputs_are_refused():
    proto = build_prototype(MECH, RIGID_NUTS, PROVIDER)
    with pytest.raises(ValueError, match=r"\(n_points, 3\)"):
        simulate(proto, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="name"):
        simulate(proto, np.zeros((1, 3)), effects=[object()])
    with pytest.raises(ValueError, match="rigid motions"):
        build_prototype(MECH, RIGID_NUTS, lambda chain, a, b: np.eye(12))
    with pytest.raises(ValueError, match="one transmission per driving chain"):
        build_prototype(MECH, RIGID_NUTS[:2], PROVIDER)


def test_assembled_tangent_is_the_derivative_of_the_residual():
    """Whole-mechanism tangent (segments + weight + nut springs) against central differences."""
    from flexcal.validation.prototype.mechanism import _loads
    from flexcal.validation.effects.hooks import PointConditions
    from flexcal.validation.prototype.equilibrium import _update, evaluate

    proto = build_prototype(MECH, RIGID_NUTS, PROVIDER)
    weight = MECH.payload_mass * np.asarray(MECH.gravity)
    centre = np.array([0.15, 0.05, 0.10])  # off the x axis, so that every load-stiffness term is non-zero
    conditions = PointConditions(segment_stiffness=proto.segment_stiffness, frame_forces=((weight, centre),),
                                 actuator_stiffness=np.full(3, MECH.actuator_stiffness))
    loads = _loads(proto, conditions, np.array([1e-4, -2e-4, 3e-4]))
    stiffness = proto.segment_stiffness.reshape(-1, 6, 6)
    rng = np.random.default_rng(7)
    n = proto.assembly.n_dofs
    # an off-equilibrium state: every body moved by ~1e-4 m / 1e-3 rad
    state = _update(proto.assembly, proto.initial_poses,
                    rng.normal(size=n) * np.where(proto.assembly.dof_is_rotation, 1e-3, 1e-4))
    _, _, tangent, _ = evaluate(proto.assembly, state, stiffness, loads)
    h = 1e-6
    columns = np.zeros((n, n))
    for b in range(n):
        step = np.zeros(n)
        step[b] = h
        plus = evaluate(proto.assembly, _update(proto.assembly, state, step), stiffness, loads, False)[1]
        minus = evaluate(proto.assembly, _update(proto.assembly, state, -step), stiffness, loads, False)[1]
        columns[:, b] = (plus - minus) / (2 * h)
    fd = 0.5 * (columns + columns.T)  # symmetrizing removes the g.[e_a, e_b]/2 part (superelement docs)
    # round-off of residuals (~1e-6 N) over 2h gives ~1 N/m; truncation ~(h/0.01 m)^2 relative
    assert np.allclose(tangent, fd, rtol=0, atol=1e-8 * np.max(np.abs(tangent)))
    # the frame block holds the weight's load stiffness (~m g x 0.15 m = 440 N m/rad): check it
    # at the FD's own noise level (~1 in these units), far below what a wrong sign would give
    assert np.allclose(tangent[:6, :6], fd[:6, :6], rtol=0, atol=5.0)


@dataclasses.dataclass
class DirectionRecorder:
    """Test effect: records the travel directions the physics hands to effects."""

    seen: list = dataclasses.field(default_factory=list)
    name: str = "direction_recorder"
    parameters: dict = dataclasses.field(default_factory=dict)

    def measure(self, angles, context):
        self.seen.append(context.direction.copy())
        return angles


def test_effects_see_the_conventional_travel_direction():
    inputs = np.array([[0, 0, 0], [1e-4, 0, 0], [1e-4, 0, 0], [0, -1e-4, 0], [0, -1e-4, 1e-10], [0, 0, 0]])
    recorder = DirectionRecorder()
    simulate(build_prototype(MECH, RIGID_NUTS, PROVIDER), inputs, effects=[recorder])
    # +1 before any move; the sign of the last move > 1 nm; holds through pauses and sub-nm jitter
    expected = [[1, 1, 1], [1, 1, 1], [1, 1, 1], [-1, -1, 1], [-1, -1, 1], [-1, 1, 1]]
    assert np.array_equal(np.array(recorder.seen), expected)
    try:
        from flexcal.model.trajectory import travel_directions
    except ImportError:
        return
    assert np.array_equal(np.array(recorder.seen), travel_directions(inputs))  # one rule for model and prototype


def test_mount_offsets_build_chains_to_fit_without_prestress():
    offsets = {"L1": (2e-3, 0.3), "L2": (1.5e-3, 2.0), "L3": (0.5e-3, 4.0)}
    proto = build_prototype(WEIGHTLESS, RIGID_NUTS, PROVIDER, mount_offsets=offsets)
    a0 = np.asarray(MECH.chains[0].point_a)
    axes = MECH.chains[0].rotation
    moved = np.asarray(proto.mechanism.chains[0].point_a)
    # round-off of ~0.5 m coordinates (1 ulp = 1e-16 m); rtol=0 (default 1e-5 hid it)
    assert np.allclose(moved - a0, 2e-3 * (np.cos(0.3) * axes[:, 1] + np.sin(0.3) * axes[:, 2]), rtol=0, atol=1e-15)
    run = simulate(proto, np.zeros((1, 3)))
    assert np.all(np.abs(run.pose) < 1e-15) and np.all(np.abs(run.axial_loads) < 1e-6)  # unstressed
    loaded = simulate(build_prototype(MECH, RIGID_NUTS, PROVIDER, mount_offsets=offsets), np.zeros((1, 3)))
    nominal = simulate(build_prototype(MECH, RIGID_NUTS, PROVIDER), np.zeros((1, 3)))
    assert np.max(np.abs(loaded.angles - nominal.angles)) > 1e-8  # the tripod's geometry changed the sag
    with pytest.raises(ValueError, match="unknown chains"):
        build_prototype(MECH, RIGID_NUTS, PROVIDER, mount_offsets={"L7": (1e-3, 0.0)})


def test_load_dependent_effect_is_solved_at_the_points_own_loads():
    """gravity_sag's stiffness is a function of the chain loads; the prototype solves it
    with the equilibrium (fixed point), so each point is the equilibrium of the stiffness
    at its *own* loads: re-solving every point on its own with the stiffness frozen at
    those loads gives the same angles (to the Newton tolerance's ~1e-11 rad), while the
    stiffness of the previous point's loads (the former one-point lag) is visibly off."""
    from flexcal.validation.effects.injectors import GravitySag

    sag = GravitySag(exponent=(0.3, 0.3, 0.3), coefficient=(0.05, 0.05, 0.05, 0.1, 0.1, 0.1))
    prototype = build_prototype(MECH, RIGID_NUTS, PROVIDER)
    inputs = np.array([[0.0, 0.0, 0.0], [0.9e-3, 0.0, 0.0], [0.9e-3, -0.9e-3, 0.0], [0.0, 0.0, 0.6e-3]])
    run = simulate(prototype, inputs, effects=[sag])

    @dataclasses.dataclass(frozen=True)
    class FrozenAt:
        loads: np.ndarray
        name: str = "frozen_gravity_sag"

        def modify_mechanism(self, conditions, context):
            return sag.modify_loaded_mechanism(conditions, self.loads, context)

    for k in range(1, len(inputs)):
        own = simulate(prototype, inputs[k:k + 1], effects=[FrozenAt(run.axial_loads[k])])
        lagged = simulate(prototype, inputs[k:k + 1], effects=[FrozenAt(run.axial_loads[k - 1])])
        assert np.max(np.abs(own.angles[0] - run.angles[k])) < 1e-10  # the Newton tolerance's ~1e-11 rad (docstring)
        assert np.max(np.abs(lagged.angles[0] - run.angles[k])) > 1e-8  # the one-point lag: > 100x the Newton tolerance


@pytest.mark.parametrize("hook", ["modify_mechanism", "modify_loaded_mechanism"])
def test_condition_hook_that_returns_something_else_is_named(hook):
    class Broken:
        name = "broken"

    setattr(Broken, hook, lambda self, conditions, *args: None)
    prototype = build_prototype(MECH, RIGID_NUTS, PROVIDER)
    # the loaded hook first runs at the first point's second iterate (no loads before)
    with pytest.raises(ValueError, match=f"{hook} of effect 'broken' must return PointConditions"):
        simulate(prototype, np.zeros((2, 3)), effects=[Broken()])
