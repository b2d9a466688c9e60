"""The mount as a structure (flexcal.validation.structure) on the prototype's reduced
model: modes, support stiffness, buckling factors and leaf stresses against closed forms
or independent computations. Beam-theory segments: each test takes about a second."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.linalg

from flexcal.geometry.frames import se3_inverse, se3_log, twist_transform
from flexcal.geometry.params import Material, reference_mechanism
from flexcal.validation.prototype.equilibrium import SolverSettings
from flexcal.validation.prototype.mechanism import FRAME_BODY, build_prototype
from flexcal.validation.prototype.segments import analytic_provider, expand_end_stiffness, rigid_transfer
from flexcal.validation.prototype.transmission import ActuatorTransmission
from flexcal.validation.structure.mount import (NominalState, chain_buckling_factors, chain_end_reduction, mount_mass, mount_modes, nominal_state,
                                                payload_mass_matrix, support_stiffness)
from flexcal.validation.structure.segment_mass import analytic_segment_mass
from flexcal.validation.structure.stress import leaf_von_mises

NOMINAL = [ActuatorTransmission()] * 3


@pytest.fixture(scope="module")
def mount():
    mechanism = reference_mechanism()
    prototype = build_prototype(mechanism, NOMINAL, analytic_provider())
    return prototype, nominal_state(prototype)


def _segment_masses(prototype, material):
    return np.array([[analytic_segment_mass(p.chain, prototype.section_x[c, s], prototype.section_x[c, s + 1], material)
                      for s in range(5)] for c, p in enumerate(prototype.mechanism.chains)])


def test_massless_chains_give_the_rigid_payload_on_its_support_stiffness(mount):
    """With (nearly) massless chains, static condensation is exact: the mount's lowest six
    modes are those of the dense 6 x 6 problem K_s phi = w^2 M_p phi, K_s the support
    stiffness at O_C (nuts on their springs), M_p the payload's rigid-body mass. Chain
    density 1e-9 of steel: relative error ~1e-9 (bound 1e-6)."""
    prototype, state = mount
    light = Material(density=7850.0 * 1e-9)
    payload = payload_mass_matrix(prototype.mechanism)
    M = mount_mass(prototype, _segment_masses(prototype, light), payload)
    modes = mount_modes(prototype, state, M, 6)
    K_s = support_stiffness(prototype, state.tangent, nuts_held=False)
    dense = np.sqrt(scipy.linalg.eigh(K_s, payload, eigvals_only=True)) / (2 * np.pi)
    # 1e-6: chain density 1e-9 of steel leaves ~1e-9 (docstring)
    np.testing.assert_allclose(modes.frequencies, dense, rtol=1e-6)
    # r^T M r: the payload's mass and its inertia about O_C (parallel axes); the frame has
    # turned by ~6e-6 rad under its weight, so its axes (in which r is taken) differ from
    # the mechanism axes by that: measured 2.3e-5 on the ry inertia, bound 1e-4
    np.testing.assert_allclose(modes.total_mass, np.diag(payload), rtol=1e-4)


def test_support_stiffness_is_the_prototype_response_to_a_small_wrench(mount):
    """Newton's nonlinear equilibrium under a small extra wrench at O_C moves the frame by
    K_s^-1 w (nuts on springs): forces of 50 N and couples of 20 N m, displacements
    ~1e-7 m and ~1e-6 rad, so the nonlinearity is ~1e-4 of the answer (bound 1e-3)."""
    prototype, state = mount
    K_s = support_stiffness(prototype, state.tangent, nuts_held=False)
    d = 0.1
    cases = [((FRAME_BODY, 50.0 * e, np.zeros(3)),) for e in np.eye(3)]
    cases += [((FRAME_BODY, 100.0 * np.roll(e, 1), d * np.roll(e, 2)), (FRAME_BODY, -100.0 * np.roll(e, 1), -d * np.roll(e, 2)))
              for e in np.eye(3)]  # couple 2 d F = 20 N m about e
    for k, extra in enumerate(cases):
        wrench = np.zeros(6)
        for _, force, point in extra:
            wrench += np.r_[force, np.cross(point, force)]
        moved = nominal_state(prototype, extra_forces=extra, start=state.poses)
        twist = se3_log(se3_inverse(state.poses[FRAME_BODY]) @ moved.poses[FRAME_BODY])
        expected = np.linalg.solve(K_s, wrench)
        # nonlinearity ~1e-4 of the answer at these loads (docstring)
        np.testing.assert_allclose(twist, expected, atol=1e-3 * np.abs(expected).max(), err_msg=f"case {k}")


def test_held_nuts_are_the_limit_of_stiff_actuators(mount):
    prototype, state = mount
    stiff = dataclasses.replace(prototype.mechanism, actuator_stiffness=1e13)
    # Newton's force tolerance 1e-3 N: 1e-5 N is below the round-off of 1e13 N/m springs
    # (the displacement it leaves, < 1e-11 m, is far below what the tangent depends on)
    loose = SolverSettings(force_tolerance=1e-3)
    stiff_state = nominal_state(build_prototype(stiff, NOMINAL, analytic_provider(), settings=loose))
    held = support_stiffness(prototype, state.tangent)
    limit = support_stiffness(prototype, stiff_state.tangent, nuts_held=False)
    # 1e13 N/m in series with chains of ~1e9 N/m: ~1e-4 of the nut-axis terms (bound 1e-3)
    np.testing.assert_allclose(limit, held, atol=1e-3 * np.abs(held).max())
    soft = support_stiffness(prototype, state.tangent, nuts_held=False)
    assert np.all(np.linalg.eigvalsh(held - soft) > -1e-6 * np.abs(held).max())  # holding only stiffens


def _pivot_provider(k: float):
    """Segments rigid (compliance 1e-10) except a rotational spring k [N m/rad] about local z
    at the middle of each leaf 1: ideal pivots."""
    def provider(chain, x_start, x_end):
        compliance = np.eye(6) * 1e-10
        for kind, a, b in chain.segments():
            if kind == "leaf1" and x_start <= a and b <= x_end:
                spring = np.zeros((6, 6))
                spring[5, 5] = 1.0 / k
                move = twist_transform(np.eye(3), np.array([0.5 * (a + b) - x_end, 0.0, 0.0]))
                compliance = compliance + move @ spring @ move.T
        k_end = np.linalg.inv(compliance)
        return expand_end_stiffness(0.5 * (k_end + k_end.T), x_end - x_start)
    return provider


PIVOT_CHAIN = 1  # L2: ground at A, frame at B


def pivot_chain_buckling(prototype, axial: float, shortening: float):
    """(``chain_buckling_factors``, L_p [m]) at a state made by hand: chain ``PIVOT_CHAIN`` under a
    pure axial compression ``axial`` [N], each of its segments shortened by ``shortening`` [m]."""
    mechanism = prototype.mechanism
    axis = mechanism.chains[PIVOT_CHAIN].rotation[:, 0]
    poses = prototype.initial_poses.copy()
    bodies = list(prototype.assembly.node_body[6 * PIVOT_CHAIN + 1:6 * PIVOT_CHAIN + 6])  # 4 interior nodes, the frame
    for k_node, body in enumerate(bodies, start=1):
        poses[body, :3, 3] -= k_node * shortening * axis
    state = NominalState(poses=poses, tangent=None, segment_gradient=None, tension=np.full(6, -axial),
                         weight_factor=1.0, commands=np.zeros(3))
    placement = mechanism.chains[PIVOT_CHAIN].chain
    return (chain_buckling_factors(prototype, state),
            placement.length - 2 * placement.end_block_length - placement.hinge_length)


def test_chain_sway_buckling_is_2k_over_L_for_ideal_pivots():
    """A chain whose only flexibility is two pivots (rotational stiffness k about local z,
    at the leaf-1 centres, L_p apart) between rigid pieces, under a pure axial compression
    N: with end B free to sway and held against turning, N_cr = 2 k / L_p (REFERENCES.md).
    The state is made by hand (each segment shortened by its axial compliance times N, so
    every segment carries N and nothing else; in the mount the chains also carry lateral
    loads and moments, which shift the factor: -0.08 % for L2 here). The rigid pieces'
    1e-10 compliance against 1/k = 5e-4 and the tangent's central differences move it
    by ~1e-6 (bound 1e-5)."""
    k, axial = 2000.0, 3000.0
    prototype = build_prototype(reference_mechanism(), NOMINAL, _pivot_provider(k))
    factors, pivots = pivot_chain_buckling(prototype, axial, axial * 1e-10)
    # 1e-5: rigid-piece compliance and central differences ~1e-6 (docstring)
    assert factors["sway"][PIVOT_CHAIN] * axial == pytest.approx(2 * k / pivots, rel=1e-5)


def test_leaf_von_mises_closed_forms():
    """Pure tension, pure bending through the thickness, pure bending across the width,
    pure torsion: N / (w t), 6 M / (w t^2), 6 M / (t w^2), sqrt(3) M / (beta w t^2)."""
    chain = reference_mechanism().chains[0].chain
    w, t = chain.width, chain.thickness_1
    zero = np.zeros(3)
    assert leaf_von_mises(chain, "leaf1", np.array([1e3, 0, 0]), zero) == pytest.approx(1e3 / (w * t))
    assert leaf_von_mises(chain, "leaf1", zero, np.array([0, 0, 5.0])) == pytest.approx(30.0 / (w * t * t))
    assert leaf_von_mises(chain, "leaf2", zero, np.array([0, 5.0, 0])) == pytest.approx(30.0 / (w * t * t))
    assert leaf_von_mises(chain, "leaf1", zero, np.array([0, 5.0, 0])) == pytest.approx(30.0 / (t * w * w))
    beta = (1 - 0.63 * t / w) / 3
    assert leaf_von_mises(chain, "leaf1", zero, np.array([2.0, 0, 0])) == pytest.approx(np.sqrt(3) * 2.0 / (beta * w * t * t))


def test_structure_command_writes_its_report(tmp_path, capsys):
    import json

    from flexcal.validation import cli

    out = tmp_path / "run"
    assert cli.main(["structure", "--trajectory-points", "13", "--modes", "8", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert len(report["modes"]["frequencies_Hz"]) == 8
    assert report["modes"]["frequencies_Hz"][0] > 0
    assert np.array(report["support_stiffness"]["nuts_held"]).shape == (6, 6)
    assert report["stress"]["yield_strength_MPa"] == 335.0
    assert (out / "report.md").read_text().startswith("# Mount structure")
    assert "total_s" in json.loads((out / "timings.json").read_text())["timings_s"]
    assert "first mode" in capsys.readouterr().out
    # mode pictures and the VTU with one displacement field per mode
    assert [p.name for p in sorted(out.glob("mode_*.png"))] == [f"mode_{k}.png" for k in range(1, 7)]
    import pyvista as pv

    grid = pv.read(out / "modes.vtu")
    assert grid.n_points == 44 and all(f"mode_{k}" in grid.point_data for k in range(1, 9))
    assert len(report["modes"]["frequencies_without_preload_Hz"]) == 8
    assert len(report["workspace"]["corners"]) == 8
    assert cli.main(["structure", "--modes", "0", "--out", str(tmp_path / "bad")]) == 2
    # a mesh option without meshed segments is refused, not ignored
    assert cli.main(["structure", "--mesher", "tetwild", "--out", str(tmp_path / "bad")]) == 2


def test_chain_reduced_to_its_ends_keeps_its_rigid_body_mass(mount):
    """Guyan onto A and B: the rigid projection of M_c equals that of the six-node chain
    (Psi reproduces rigid motions; round-off), and K_c vanishes on rigid motions."""
    prototype, _ = mount
    masses = _segment_masses(prototype, prototype.mechanism.material)
    for c in (0, 3):
        K_c, M_c = chain_end_reduction(prototype, masses, c)
        x = prototype.section_x[c]
        full = np.zeros((36, 36))
        for s in range(5):
            full[6 * s:6 * s + 12, 6 * s:6 * s + 12] += masses[c, s]
        R = np.concatenate(list(rigid_transfer(x)))  # node k's motion for a rigid twist at A
        R_ends = np.concatenate([R[:6], R[30:]])
        expected = R.T @ full @ R
        # round-off of a 36-DOF static condensation
        np.testing.assert_allclose(R_ends.T @ M_c @ R_ends, expected, atol=1e-9 * np.abs(expected).max())
        # K_c on rigid motions: round-off of stiffnesses up to ~1e10
        assert np.abs(K_c @ R_ends).max() < 1e-6 * np.abs(K_c).max()


def test_mirror_map_turns_a_first_half_slice_into_its_second_half_twin():
    """The FEM segments are built for the first half of a chain and mirrored (stiffness,
    mass, and the node motions for stresses, all through one P); beam theory, which
    builds both halves directly, agrees: K(L - b, L - a) = P K(a, b) P^T (round-off)."""
    from flexcal.validation.prototype.segments import section_nodes
    from flexcal.validation.structure.fem_segments import mirror_map

    chain = reference_mechanism().chains[3].chain
    x = section_nodes(chain)
    provider, P = analytic_provider(), mirror_map()
    for a, b in ((x[0], x[1]), (x[1], x[2])):
        first = provider(chain, a, b)
        second = provider(chain, chain.length - b, chain.length - a)
        # round-off of the beam-theory inversions (entries up to ~1e10)
        np.testing.assert_allclose(second, P @ first @ P.T, atol=1e-9 * np.abs(first).max())
        first_m = analytic_segment_mass(chain, a, b)
        second_m = analytic_segment_mass(chain, chain.length - b, chain.length - a)
        # same pieces, mirrored: round-off
        np.testing.assert_allclose(second_m, P @ first_m @ P.T, atol=1e-12 * np.abs(first_m).max())


@pytest.mark.parametrize("mesher", ["mapped", pytest.param("tetwild", marks=pytest.mark.slow)])
def test_fem_segment_keeps_the_rigid_body_mass(tmp_path, mesher):
    """A meshed strut slice (50 x 50 x 15 mm block; mapped: 2.5k DOF, ~1 s; CadQuery and
    fTetWild: ~300 DOF, 5-13 s): its Guyan mass keeps the block's rigid-body mass at node
    A (the box's volume is exact: measured 1.3e-15 for the snapped fTetWild mesh), its
    stiffness is symmetric."""
    from flexcal.fem.mass import box_inertia, rigid_body_mass
    from flexcal.validation.prototype.segments import rigid_transfer, section_nodes
    from flexcal.validation.structure.fem_segments import FemSegments

    chain = reference_mechanism().chains[3].chain
    x = section_nodes(chain)
    segments = FemSegments(cache_directory=tmp_path, mesher=mesher)
    M = segments.mass(chain, x[2], x[3])
    length = x[3] - x[2]
    mass = 7850.0 * chain.section**2 * length
    expected = rigid_body_mass(mass, box_inertia(mass, [length, chain.section, chain.section]),
                               np.array([length / 2, 0, 0]), np.zeros(3))
    R = np.vstack([np.eye(6), rigid_transfer(length)])
    # round-off (measured 1.3e-15); 1e-10 leaves room for another mesh of the same box
    np.testing.assert_allclose(R.T @ M @ R, expected, atol=1e-10 * np.abs(expected).max())
    K = segments(chain, x[2], x[3])
    assert np.array_equal(K, K.T)
