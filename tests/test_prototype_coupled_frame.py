"""The prototype's frame with coupled segments (superelement.CoupledStiffness; docs/meshing.md,
"Session 24: the tied-cut frame"): energy 1/2 Xi^T K Xi per group of segments."""

import numpy as np
import pytest

from flexcal.validation.prototype.equilibrium import Loads, _update, build_assembly, evaluate
from flexcal.validation.prototype.kinematics import pose, se3_exp, translation_pose
from flexcal.validation.prototype.superelement import CoupledStiffness

N_SEGMENTS = 5


def _two_chains(rng):
    """Two chains of five segments from ground to one shared free body (like the prototype's
    chains to its frame), four free interior bodies each, bent and twisted far from their
    undeformed poses; (assembly, body poses)."""
    n_bodies = 1 + 2 * 4 + 1  # end body, interior bodies, ground
    ground, end = n_bodies - 1, 0
    selection = [np.eye(6)] * (n_bodies - 1) + [np.zeros((6, 0))]
    lengths = np.array([0.03, 0.02, 0.05, 0.02, 0.03])
    x = np.concatenate([[0.0], np.cumsum(lengths)])
    poses = np.broadcast_to(np.eye(4), (n_bodies, 4, 4)).copy()
    node_body, node_offset, segments, references = [], [], [], []
    for c, y in enumerate((0.0, 0.04)):
        starts = pose(np.eye(3), np.array([0.0, y, 0.0]))
        chain_nodes = starts @ se3_exp(np.array([[xk, 0, 0, 0, 0, 0] for xk in x]))
        node_body.append(ground)
        node_offset.append(chain_nodes[0])
        for k in range(4):
            body = 1 + 4 * c + k
            poses[body] = chain_nodes[k + 1]
            node_body.append(body)
            node_offset.append(np.eye(4))
        node_body.append(end)
        node_offset.append(chain_nodes[5] if c == 0 else np.linalg.inv(poses[end]) @ chain_nodes[5])
        if c == 0:
            poses[end], node_offset[-1] = chain_nodes[5], np.eye(4)
        for s in range(N_SEGMENTS):
            segments.append((6 * c + s, 6 * c + s + 1))
            references.append(translation_pose(np.array([-lengths[s], 0.0, 0.0])))
    assembly = build_assembly(selection, node_body, np.array(node_offset), segments, np.array(references))
    moved = poses[:-1] @ se3_exp(np.column_stack([rng.normal(0, 2e-3, (n_bodies - 1, 3)),
                                                  rng.normal(0, 0.1, (n_bodies - 1, 3))]))
    return assembly, np.concatenate([moved, poses[-1:]])


def _spd(rng, n, units):
    """A random symmetric positive definite (n, n) in the DOFs' ``units`` (rotations about m)."""
    a = rng.normal(size=(n, n))
    k = a @ a.T + n * np.eye(n)
    return 1e6 * k / units[:, None] / units[None, :]


UNITS = np.r_[np.ones(3), np.full(3, 0.02)]  # [m] per unit DOF: rotations as displacements 20 mm out


def test_block_diagonal_coupled_stiffness_is_the_uncoupled_frame():
    rng = np.random.default_rng(0)
    assembly, poses = _two_chains(rng)
    kjj = np.array([_spd(rng, 6, UNITS) for _ in range(2 * N_SEGMENTS)])
    blocks = np.zeros((2, 30, 30))
    for c in range(2):
        for s in range(N_SEGMENTS):
            blocks[c, 6 * s:6 * s + 6, 6 * s:6 * s + 6] = kjj[N_SEGMENTS * c + s]
    coupled = CoupledStiffness(blocks=blocks, segments=np.arange(10).reshape(2, 5))
    np.testing.assert_array_equal(coupled.diagonal(), kjj)
    today = evaluate(assembly, poses, kjj, Loads())
    tied = evaluate(assembly, poses, coupled, Loads())
    # the same sums in another order (K Xi over 30 terms, 24 of them exact zeros): round-off
    # ~1e-16 of the largest term; 1e-12
    assert tied[0] == pytest.approx(today[0], rel=1e-12)
    for a, b in ((tied[1], today[1]), (tied[3], today[3])):
        # as above: round-off of the same sums in another order; 1e-12
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max(), np.abs(a - b).max() / np.abs(b).max()
    # the tangent is a central difference (step 1e-6) of gradients that now differ by round-off
    # (~1e-16 of K xi), which the difference amplifies by ~1e6: measured 5.4e-12 of the
    # largest entry; 1e-9 (the tangent's own round-off, superelement.DEFAULT_STEP)
    assert np.abs(tied[2] - today[2]).max() <= 1e-9 * np.abs(today[2]).max()


def _coupled(rng):
    blocks = np.array([_spd(rng, 30, np.tile(UNITS, 5)) for _ in range(2)])
    return CoupledStiffness(blocks=blocks, segments=np.array([[5, 6, 7, 8, 9], [0, 1, 2, 3, 4]]))


def test_coupled_residual_is_the_gradient_of_its_energy_and_its_tangent_the_hessian():
    rng = np.random.default_rng(1)
    assembly, poses = _two_chains(rng)
    stiffness = _coupled(rng)
    # the random groups couple their segments strongly (0.1: an off-diagonal block a tenth of a diagonal one)
    assert np.abs(stiffness.blocks[0, :6, 6:]).max() > 0.1 * np.abs(stiffness.blocks[0, :6, :6]).max()
    energy, residual, tangent, _ = evaluate(assembly, poses, stiffness, Loads())
    scale = np.where(assembly.dof_is_rotation, 0.02, 1.0)  # [m] per unit DOF
    h = 1e-6
    gradient, jacobian = np.zeros(assembly.n_dofs), np.zeros((assembly.n_dofs, assembly.n_dofs))
    for b in range(assembly.n_dofs):
        step = np.zeros(assembly.n_dofs)
        step[b] = h / scale[b]
        plus = evaluate(assembly, _update(assembly, poses, step), stiffness, Loads(), False)
        minus = evaluate(assembly, _update(assembly, poses, -step), stiffness, Loads(), False)
        gradient[b] = (plus[0] - minus[0]) / (2 * step[b])
        jacobian[:, b] = (plus[1] - minus[1]) / (2 * step[b])
    # central differences (h = 1e-6 m or 1e-6 x 20 mm): truncation O(h^2 / 2 cm^2) ~1e-9,
    # round-off ~1e-16 of the energy / h against the residual; measured 7e-11 of the largest
    # residual component; 1e-6
    assert np.abs(gradient - residual).max() <= 1e-6 * np.abs(residual).max()  # 1e-6: see above
    # the residual's manifold derivative is the Hessian plus a part antisymmetric in (a, b)
    # (superelement docstring): its symmetric part is the tangent. Both are central differences
    # (the tangent's own of each segment's gradient), measured 2.6e-11 of the largest entry; 1e-6
    symmetric = 0.5 * (jacobian + jacobian.T)
    error = np.abs(symmetric - tangent).max() / np.abs(tangent).max()
    assert error <= 1e-6, error  # 1e-6: see above
    # the cross-segment blocks matter: without them the tangent is off by 0.19 of its largest
    # entry; 1e-2
    uncoupled = evaluate(assembly, poses, CoupledStiffness(blocks=stiffness.blocks * np.kron(
        np.eye(5), np.ones((6, 6))), segments=stiffness.segments), Loads())[2]
    assert np.abs(uncoupled - tangent).max() > 1e-2 * np.abs(tangent).max()  # 1e-2: see above


def test_a_coupled_stiffness_must_cover_each_segment_once():
    with pytest.raises(ValueError, match="one group only"):
        CoupledStiffness(blocks=np.zeros((2, 30, 30)), segments=np.array([[0, 1, 2, 3, 4], [4, 5, 6, 7, 8]]))
    with pytest.raises(ValueError, match="n_groups, 6 m, 6 m"):
        CoupledStiffness(blocks=np.zeros((2, 30, 30)), segments=np.arange(8).reshape(2, 4))


def _block_diagonal_provider():
    """The analytic provider, also giving each chain's K_chain as the block diagonal of its
    segments' K_jj (what rigid ties are, ``flexcal.fem.cut_warping``)."""
    from flexcal.validation.prototype.segments import analytic_provider, section_nodes

    base = analytic_provider()

    def provider(chain, x_start, x_end):
        return base(chain, x_start, x_end)

    def chain_stiffness(chain):
        nodes = section_nodes(chain)
        out = np.zeros((30, 30))
        for s in range(N_SEGMENTS):
            out[6 * s:6 * s + 6, 6 * s:6 * s + 6] = base(chain, float(nodes[s]), float(nodes[s + 1]))[6:, 6:]
        return out

    provider.chain_stiffness = chain_stiffness
    return provider


class _Softer:
    name = "softer"

    def modify_stiffness(self, stiffness, context):
        return 0.99 * stiffness


def test_a_prototype_whose_chains_carry_their_block_diagonal_is_todays_with_and_without_stiffness_effects():
    from flexcal.geometry.params import reference_mechanism
    from flexcal.validation.prototype.mechanism import build_prototype, simulate
    from flexcal.validation.prototype.segments import analytic_provider
    from flexcal.validation.prototype.transmission import ActuatorTransmission

    mechanism = reference_mechanism()
    transmissions = [ActuatorTransmission(initial_position=-0.20e-3, clearance=0.42e-3, hysteresis=0.83)] * 3
    inputs = np.array([[0, 0, 0], [0.5e-3, 0, 0], [0.5e-3, -0.4e-3, 0.2e-3], [0, 0, -0.6e-3]])
    today = simulate(build_prototype(mechanism, transmissions, analytic_provider()), inputs)
    tied_prototype = build_prototype(mechanism, transmissions, _block_diagonal_provider())
    assert tied_prototype.chain_stiffness.shape == (6, 30, 30)
    tied = simulate(tied_prototype, inputs)
    # both converge to the same equilibria within Newton's tolerances (1e-5 N, 1e-5 N m: < 1e-11
    # rad, SolverSettings); angles ~1e-3 rad; measured 0 (the same iterates); 1e-10 rad
    assert np.abs(tied.true_angles - today.true_angles).max() <= 1e-10
    assert np.abs(tied.axial_loads - today.axial_loads).max() <= 1e-4  # [N] of ~3e3 N: the load tolerance; measured 0
    # an effect on the K_jj acts on K_chain by the segments' congruences (docs/effects.md, "Effects
    # on tied cuts"), which on a block diagonal is the same change: the same equilibria as today's
    # with the effect, to Newton's tolerance as above (measured 2e-14 rad); 1e-10 rad
    softer_today = simulate(build_prototype(mechanism, transmissions, analytic_provider()), inputs, effects=[_Softer()])
    softer_tied = simulate(tied_prototype, inputs, effects=[_Softer()])
    assert np.abs(softer_tied.true_angles - softer_today.true_angles).max() <= 1e-10  # see above
    assert np.abs(softer_tied.true_angles - tied.true_angles).max() > 1e-7  # the effect moves them (measured 9e-7 rad)


def test_the_tied_provider_names_its_cuts_and_refuses_what_it_cannot_tie():
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.tied_chains import cut_interfaces, tied_fem_provider

    assert cut_interfaces("d12/p8") == ("d12", "p8", "p8", "d12")  # m1, s0, s1, m2
    assert cut_interfaces("d12") == ("d12",) * 4
    provider = stiffness_provider("fem", progress=False)
    assert callable(provider.chain_stiffness) and "d12/p8" in provider.description
    assert not hasattr(stiffness_provider("fem-rigid", progress=False), "chain_stiffness")  # rigid ties
    with pytest.raises(ValueError, match="unknown ties"):
        tied_fem_provider("d7")
    with pytest.raises(ValueError, match="mapped mesher"):
        tied_fem_provider("d12/p8", mesher="tetwild")
