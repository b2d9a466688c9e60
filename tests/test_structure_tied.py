"""The structure assessment of a prototype whose cuts are tied (``Prototype.chain_stiffness``:
each chain's K_chain on its five segments' twists; docs/structure.md, "Tied cuts"), on
beam-theory segments: (a) a tied prototype whose K_chain is the block diagonal of its K_jj is
today's rigidly tied one, figure by figure; (b) a genuinely coupled K_chain (the segments'
compliance plus an axial compliance shared by all five, which couples every pair) is checked
against an independent computation (the chains' linear stiffness reduced onto their ends and
summed at O_C) and against the order it must keep (less stiffness, lower frequencies). Each
test takes a few seconds."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from flexcal.geometry.params import Material, reference_mechanism
from flexcal.validation.prototype.kinematics import se3_adjoint, se3_inverse
from flexcal.validation.prototype.mechanism import build_prototype
from flexcal.validation.prototype.segments import analytic_provider, section_nodes
from flexcal.validation.prototype.transmission import ActuatorTransmission
from flexcal.validation.structure.mount import (chain_buckling_factors, chain_end_reduction, mount_buckling_factor,
                                                mount_mass, mount_modes, nominal_state, payload_mass_matrix,
                                                support_stiffness)
from flexcal.validation.structure.segment_mass import analytic_segment_mass
from flexcal.validation.structure.stress import chain_peak_stress_beam

NOMINAL = [ActuatorTransmission()] * 3
N_SEGMENTS = 5
SHARED_AXIAL = 0.01
"""The coupled K_chain's shared axial compliance, as a fraction of the chain's own (rigid ties)
axial compliance per segment slot: 25 x 0.01 = 25 % more end-to-end axial compliance, about what
the tied truth's chains have (19-23 % too stiff with rigid ties)."""


def _block_diagonal(chain, base=None):
    base = base or analytic_provider()
    nodes = section_nodes(chain)
    out = np.zeros((30, 30))
    for s in range(N_SEGMENTS):
        out[6 * s:6 * s + 6, 6 * s:6 * s + 6] = base(chain, float(nodes[s]), float(nodes[s + 1]))[6:, 6:]
    return out


def _axial_compliance(K: np.ndarray) -> float:
    """[m/N] end B along the chain, A clamped, of a chain whose K_chain is the block diagonal
    ``K`` (30, 30): the sum of its segments' axial compliances (straight chain, node axes along it)."""
    return sum(np.linalg.inv(K[6 * s:6 * s + 6, 6 * s:6 * s + 6])[0, 0] for s in range(N_SEGMENTS))


def _tied_provider(shared: float | None, base=None):
    """``base`` (default the analytic provider) with ``chain_stiffness``: the block diagonal of the
    segments' K_jj (``shared`` None: what rigid ties are), or the inverse of their compliance plus
    ``c a a^T``, a the five segments' axial twists, c = ``shared`` x the chain's axial compliance
    (Sherman-Morrison: K - c K a a^T K / (1 + c a^T K a))."""
    base = base or analytic_provider()

    def provider(chain, x_start, x_end):
        return base(chain, x_start, x_end)

    def chain_stiffness(chain):
        K = _block_diagonal(chain, base)
        if shared is None:
            return K
        c = shared * _axial_compliance(K)
        a = np.zeros(30)
        a[0::6] = 1.0
        Ka = K @ a
        return K - c * np.outer(Ka, Ka) / (1.0 + c * a @ Ka)

    provider.chain_stiffness = chain_stiffness
    return provider


def _masses(prototype, material):
    return np.array([[analytic_segment_mass(p.chain, prototype.section_x[c, s], prototype.section_x[c, s + 1], material)
                      for s in range(N_SEGMENTS)] for c, p in enumerate(prototype.mechanism.chains)])


@pytest.fixture(scope="module")
def mounts():
    mechanism = reference_mechanism()
    out = {}
    for name, provider in (("rigid", analytic_provider()), ("block_diagonal", _tied_provider(None)),
                           ("coupled", _tied_provider(SHARED_AXIAL))):
        prototype = build_prototype(mechanism, NOMINAL, provider)
        out[name] = (prototype, nominal_state(prototype), nominal_state(prototype, 0.0))
    return out


def _relative(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(b)).max()


def test_block_diagonal_ties_give_todays_figures(mounts):
    rigid, rigid_loaded, rigid_unloaded = mounts["rigid"]
    tied, loaded, unloaded = mounts["block_diagonal"]
    assert tied.chain_stiffness is not None and rigid.chain_stiffness is None
    # Newton reaches the same equilibrium (tolerances 1e-5 N, 1e-5 N m: < 1e-11 rad); the
    # coupled sums differ from today's by round-off (~1e-16 of K xi), which the tangent's
    # central differences amplify by ~1e6 (test_prototype_coupled_frame: 5e-12); 1e-10
    assert _relative(loaded.poses, rigid_loaded.poses) <= 1e-10  # see above
    assert _relative(loaded.segment_gradient, rigid_loaded.segment_gradient) <= 1e-10  # as above
    assert _relative(loaded.tangent, rigid_loaded.tangent) <= 1e-10  # as above
    # every figure below is a smooth function of those: the same 1e-10
    np.testing.assert_allclose(support_stiffness(tied, loaded.tangent), support_stiffness(rigid, rigid_loaded.tangent),
                               rtol=1e-10, atol=1e-10 * np.abs(support_stiffness(rigid, rigid_loaded.tangent)).max())  # as above
    M = mount_mass(rigid, _masses(rigid, rigid.mechanism.material), payload_mass_matrix(rigid.mechanism))
    np.testing.assert_allclose(mount_modes(tied, loaded, M, 8).frequencies,
                               mount_modes(rigid, rigid_loaded, M, 8).frequencies, rtol=1e-10)  # as above
    assert mount_buckling_factor(unloaded, loaded) == pytest.approx(
        mount_buckling_factor(rigid_unloaded, rigid_loaded), rel=1e-9)  # as above; a ratio of small differences: 1e-9
    for case, factors in chain_buckling_factors(tied, loaded).items():
        np.testing.assert_allclose(factors, chain_buckling_factors(rigid, rigid_loaded)[case], rtol=1e-9)  # as above
    np.testing.assert_allclose(chain_peak_stress_beam(tied, loaded.segment_gradient),
                               chain_peak_stress_beam(rigid, rigid_loaded.segment_gradient), rtol=1e-10)  # as above
    masses = _masses(rigid, rigid.mechanism.material)
    for c in (0, 3):
        # J^T blockdiag(K_jj) J against the 12 x 12 summed: the analytic 12 x 12 is J_s^T K_jj J_s
        # (expand_end_stiffness) up to round-off of entries up to ~1e10; 1e-10
        K_t, M_t = chain_end_reduction(tied, masses, c)
        K_r, M_r = chain_end_reduction(rigid, masses, c)
        assert _relative(K_t, K_r) <= 1e-10 and _relative(M_t, M_r) <= 1e-10  # see above


def _support_from_chain_ends(prototype, masses) -> np.ndarray:
    """6 x 6 at O_C, nuts held, from each chain's end reduction (``chain_end_reduction``: J^T K_chain J
    with tied cuts), A clamped, B on the frame: sum_c X_c^T K_c,BB X_c, X_c the map of the frame's
    twist to node B's (node axes). Linear: the unloaded mount's support stiffness."""
    a = prototype.assembly
    out = np.zeros((6, 6))
    for c in range(6):
        K_c, _ = chain_end_reduction(prototype, masses, c)
        X = se3_adjoint(se3_inverse(a.node_offset[6 * c + 5]))
        out += X.T @ K_c[6:, 6:] @ X
    return out


def test_coupled_ties_support_stiffness_is_the_chains_reduced_to_their_ends(mounts):
    """The tangent of the coupled frame (segment blocks by central differences with the other
    segments' share held, cross blocks J_s^T K_st J_t) at the unloaded state against the chains'
    linear K_chain mapped onto their nodes and condensed onto the ends, summed at O_C."""
    for name in ("rigid", "coupled"):
        prototype, _, unloaded = mounts[name]
        masses = _masses(prototype, prototype.mechanism.material)
        expected = _support_from_chain_ends(prototype, masses)
        # the tangent's central differences (~1e-10 relative, superelement.DEFAULT_STEP) and the
        # state's residual preload (weight 0: the nuts' springs at rest, loads ~1e-5 N); 1e-7
        np.testing.assert_allclose(support_stiffness(prototype, unloaded.tangent), expected,
                                   atol=1e-7 * np.abs(expected).max(), err_msg=name)  # see above


def test_coupled_chains_are_softer_along_their_axes_by_the_shared_compliance(mounts):
    prototype, _, _ = mounts["coupled"]
    rigid, _, _ = mounts["rigid"]
    masses = _masses(prototype, prototype.mechanism.material)
    for c in (0, 3):
        K_c, _ = chain_end_reduction(prototype, masses, c)
        K_r, _ = chain_end_reduction(rigid, masses, c)
        # end B along the chain, A clamped: the rigid compliance plus c a^T a = 25 c exactly
        # (a straight chain; the axial twists add up); round-off of the condensation: 1e-9
        expected = np.linalg.inv(K_r[6:, 6:])[0, 0] * (1.0 + 25 * SHARED_AXIAL)
        assert np.linalg.inv(K_c[6:, 6:])[0, 0] == pytest.approx(expected, rel=1e-9)  # see above


def test_coupled_ties_lower_the_support_stiffness_and_every_payload_mode(mounts):
    """K_chain <= blockdiag(K_jj) (added compliance), so at the unloaded state the support
    stiffness drops in the Loewner order and, with the same mass, every frequency drops
    (Courant-Fischer); the payload's modes on massless chains are the 6 x 6 problem's."""
    rigid, _, rigid_unloaded = mounts["rigid"]
    tied, loaded, unloaded = mounts["coupled"]
    held_rigid = support_stiffness(rigid, rigid_unloaded.tangent)
    held_tied = support_stiffness(tied, unloaded.tangent)
    drop = np.linalg.eigvalsh(held_rigid - held_tied)
    # >= 0 up to the tangents' central differences (~1e-10 of the largest entry); 1e-8
    assert drop.min() >= -1e-8 * np.abs(held_rigid).max()
    # the translations, which the chains carry axially, lose ~20 % (25 % more axial compliance)
    ratio = np.diag(held_tied)[:3] / np.diag(held_rigid)[:3]
    assert np.all((ratio > 0.75) & (ratio < 0.9)), ratio  # 0.8 for chains purely axial; bending adds some back
    light = Material(density=7850.0 * 1e-9)
    payload = payload_mass_matrix(tied.mechanism)
    M = mount_mass(tied, _masses(tied, light), payload)
    f_tied = mount_modes(tied, unloaded, M, 6).frequencies
    f_rigid = mount_modes(rigid, rigid_unloaded, M, 6).frequencies
    assert np.all(f_tied < f_rigid * (1 - 1e-3)), (f_tied, f_rigid)  # each lower, by more than round-off
    # massless chains: static condensation is exact (chain density 1e-9 of steel: ~1e-9; 1e-6)
    K_s = support_stiffness(tied, loaded.tangent, nuts_held=False)
    dense = np.sqrt(scipy.linalg.eigh(K_s, payload, eigvals_only=True)) / (2 * np.pi)
    np.testing.assert_allclose(mount_modes(tied, loaded, M, 6).frequencies, dense, rtol=1e-6)  # 1e-6: see above


def test_coupled_ties_buckling_factors_are_the_linearization_of_newtons_tangent(mounts):
    """The mount's factor s makes K_0 + s (K_T - K_0) singular (checked directly), and a chain's
    factors are finite for the compressed chains only, as with rigid ties."""
    tied, loaded, unloaded = mounts["coupled"]
    factor = mount_buckling_factor(unloaded, loaded)
    K0 = 0.5 * (unloaded.tangent + unloaded.tangent.T)
    dK = 0.5 * (loaded.tangent + loaded.tangent.T) - K0
    lowest = scipy.linalg.eigh(K0 + factor * dK, K0, eigvals_only=True, subset_by_index=[0, 0])[0]
    assert abs(lowest) <= 1e-6  # an eigenvalue of the pencil at 0 to the eigensolver's tolerance (~1e-10); 1e-6
    chains = chain_buckling_factors(tied, loaded)
    compressed = loaded.tension < 0
    assert np.all(np.isfinite(chains["held"][compressed])) and np.all(np.isinf(chains["held"][~compressed]))


def test_coupled_ties_keep_the_sway_buckling_of_ideal_pivots():
    """test_structure's chain of two pivots (k about local z, L_p apart) between rigid pieces,
    now with a shared axial compliance coupling its five segments: under a pure axial
    compression N every segment still carries N alone (statics), only the shortening grows,
    so N_cr = 2 k / L_p still. The state is made by hand: each segment shortened by N (its own
    1e-10 m/N + 5 c), c the shared compliance (0.01 of the chain's: the off-diagonal blocks ~0.04
    of the diagonal; a segment's geometric stiffness from its own block alone, K_ss xi_s instead
    of its share (K Xi)_s, would see an axial force ~20 % off). Measured 4.9e-8 from 2 k / L_p.
    A hundred times more shared compliance (shortening 26x) moves the factor by -0.36 %, the
    same to 5e-11 as rigid ties with that axial compliance per segment: the pre-buckling
    shortening of the linearization, not the coupling (2026-11-29). Bound 1e-5 as there
    (central differences ~1e-6)."""
    from test_structure import PIVOT_CHAIN, _pivot_provider, pivot_chain_buckling

    k, axial, shared = 2000.0, 3000.0, 0.01
    prototype = build_prototype(reference_mechanism(), NOMINAL, _tied_provider(shared, _pivot_provider(k)))
    K = prototype.chain_stiffness[PIVOT_CHAIN]
    # coupled: off-diagonal blocks ~0.04 of the diagonal ones (1e-2)
    assert np.abs(K[0:6, 6:12]).max() > 1e-2 * np.abs(K[0:6, 0:6]).max()
    # each segment: its own compliance 1e-10 m/N + a^T a c, c = shared x 5e-10 m/N
    factors, pivots = pivot_chain_buckling(prototype, axial, axial * (1e-10 + 5 * shared * 5e-10))
    assert factors["sway"][PIVOT_CHAIN] * axial == pytest.approx(2 * k / pivots, rel=1e-5)  # 1e-5: see the docstring


def test_a_chain_alone_has_the_mounts_tangent_on_its_interior_nodes(mounts):
    """The chain buckling's matrices (the chain alone on its section nodes) against the mount's
    tangent at the same state: on the four interior nodes only that chain's segments act."""
    from flexcal.validation.prototype.mechanism import INTERIOR_BODIES
    from flexcal.validation.structure.mount import _chain_matrices

    prototype, loaded, _ = mounts["coupled"]
    start = prototype.assembly.dof_start
    for c in (1, 4):
        K0, dK = _chain_matrices(prototype, loaded, c)
        mount = np.concatenate([start[b] + np.arange(6) for b in INTERIOR_BODIES[c]])
        expected = loaded.tangent[np.ix_(mount, mount)]
        # the same sums (central differences of the same gradients): round-off; 1e-9
        assert _relative((K0 + dK)[6:30, 6:30], expected) <= 1e-9


@pytest.fixture(scope="module")
def tied_truth():
    """The reference mount with the provider fem (cuts tied d12/p8), built once (cold ~50 s of CPU for
    its two tied chains; then from the FEM cache)."""
    from flexcal.validation.prototype.providers import stiffness_provider

    return build_prototype(reference_mechanism(), NOMINAL, stiffness_provider("fem", progress=False))


@pytest.mark.slow
def test_the_tied_truth_is_softer_than_its_rigid_ties_in_every_direction(tied_truth):
    """The tied provider's K_jj are its own condensations with the cut fields held rigid, a
    constraint on its K_chain's: K_chain <= blockdiag(K_jj). So the unloaded mount with the
    tied frame is softer than the same prototype joined rigidly (its K_jj) in the Loewner order,
    and every frequency on the same mass is lower; the chains' axial compliance (19-23 % with
    rigid ties, docs/meshing.md) shows in the translations."""
    import dataclasses

    tied = tied_truth
    unloaded = nominal_state(tied, 0.0)
    rigid = dataclasses.replace(tied, chain_stiffness=None)  # the same K_jj, joined rigidly
    rigid_unloaded = nominal_state(rigid, 0.0)
    held_tied = support_stiffness(tied, unloaded.tangent)
    held_rigid = support_stiffness(rigid, rigid_unloaded.tangent)
    # >= 0 up to the tangents' central differences (~1e-10 of the largest entry); 1e-8
    assert np.linalg.eigvalsh(held_rigid - held_tied).min() >= -1e-8 * np.abs(held_rigid).max()
    ratio = np.diag(held_tied)[:3] / np.diag(held_rigid)[:3]
    assert np.all(ratio < 0.9), ratio  # the chains' 19-23 % of axial compliance: translations lose > 10 %
    M = mount_mass(tied, _masses(tied, tied.mechanism.material), payload_mass_matrix(tied.mechanism))
    f_tied = mount_modes(tied, unloaded, M, 6).frequencies
    f_rigid = mount_modes(rigid, rigid_unloaded, M, 6).frequencies
    assert np.all(f_tied < f_rigid), (f_tied, f_rigid)


def test_stress_twists_carry_each_segments_share_of_the_chains_wrench(mounts):
    """``stress_twists`` gives each slice (start held) the end motion under which it carries
    the segment's load: with rigid ties its deformation twist, with tied cuts K_jj^-1 (K Xi)_s,
    the share the equilibrium's segment gradient holds (g_end = J_r(xi)^-T (K Xi)_s). The
    analytic provider stands in for the FEM segments (the same 12 x 12 as the prototype's)."""
    from flexcal.validation.prototype.equilibrium import node_poses
    from flexcal.validation.prototype.superelement import relative_pose, segment_deformation
    from flexcal.validation.prototype.kinematics import se3_right_jacobian_inverse
    from flexcal.validation.structure.fem_segments import stress_twists

    slices = analytic_provider()
    rigid, rigid_loaded, _ = mounts["rigid"]
    tied, loaded, _ = mounts["block_diagonal"]
    # K_jj^-1 (K_jj xi) against xi: round-off of a 6 x 6 solve (condition ~1e6; measured 3e-15); 1e-9
    assert _relative(stress_twists(tied, loaded.poses, slices), stress_twists(rigid, rigid_loaded.poses, slices)) <= 1e-9
    prototype, state, _ = mounts["coupled"]
    twists = stress_twists(prototype, state.poses, slices).reshape(-1, 6)
    a = prototype.assembly
    nodes = node_poses(a, state.poses)
    xi = segment_deformation(relative_pose(nodes[a.segment_nodes[:, 0]], nodes[a.segment_nodes[:, 1]]),
                             a.segment_reference_inverse)
    share = np.linalg.solve(np.swapaxes(se3_right_jacobian_inverse(xi), -1, -2), state.segment_gradient[:, 6:, None])[..., 0]
    carried = np.einsum("sij,sj->si", prototype.segment_stiffness.reshape(-1, 6, 6), twists)
    # the same wrench by two paths (CoupledStiffness.wrench and the gradient's offset): round-off
    # (measured 1.5e-16); 1e-9
    assert _relative(carried, share) <= 1e-9
    # and not the twist itself: the shared axial compliance moves the axial twists by ~20 % (measured 0.196); 0.1
    assert _relative(twists[:, 0], xi[:, 0]) > 0.1
