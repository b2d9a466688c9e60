"""Interfaces at a cut richer than a rigid tie (flexcal.fem.interface, the kinematic and
distributing couplings in flexcal.fem.condense.mirrored_coupled_stiffness; docs/meshing.md,
"Session 23: how rich the interface at a cut must be")."""

import numpy as np
import pytest

from flexcal.fem.condense import mirrored_coupled_stiffness
from flexcal.fem.coupling import RigidCoupling
from flexcal.fem.interface import (RIGID, DistributingCoupling, PolynomialCoupling, condensed_onto_ends,
                                   face_mass_matrix, face_triangles, n_interface_dofs, polynomial_exponents,
                                   section_mode_parity, section_modes, section_turn_signs, series_stiffness,
                                   shared_interfaces, split_at_section, turned_segment_stiffness)
from flexcal.fem.structured import grid_tet_mesh
from flexcal.geometry.params import STEEL
from test_mesh_mapped_chain_mirror import _mirrored

LENGTH, HALF = 0.06, 0.01  # a 60 mm steel bar of 20 x 20 mm section, cut at its middle
CENTRE = np.array([0.5 * LENGTH, 0.0, 0.0])


def _bar(x0: float, x1: float, n_x: int, quadrant: bool = False):
    across = np.linspace(0.0, HALF, 3) if quadrant else np.linspace(-HALF, HALF, 4)
    return grid_tet_mesh(np.linspace(x0, x1, n_x + 1), across, across)


def _face(mesh, x: float) -> np.ndarray:
    return np.flatnonzero(np.abs(mesh.nodes[:, 0] - x) < 1e-12)


def _end(mesh, x: float) -> RigidCoupling:
    return RigidCoupling(nodes=_face(mesh, x), reference_point=np.array([x, 0.0, 0.0]))


def _ends(mesh):
    return _end(mesh, 0.0), _end(mesh, LENGTH)


def _cut(kind: str, mesh, order):
    nodes = _face(mesh, CENTRE[0])
    if kind == "rigid":
        return RigidCoupling(nodes=nodes, reference_point=CENTRE)
    if kind == "kinematic":
        return PolynomialCoupling(nodes=nodes, reference_point=CENTRE, order=order, scale=HALF)
    return DistributingCoupling(nodes=nodes, reference_point=CENTRE, order=order, scale=HALF)


def _one_piece(kind: str, order, mesh=None, axes=()):
    """The bar in one piece with the cut face coupled (kinematic or rigid), the cut's DOFs
    condensed out: (12, 12)."""
    mesh = _bar(0.0, LENGTH, 8) if mesh is None else mesh
    a, b = _ends(mesh)
    return condensed_onto_ends(mirrored_coupled_stiffness(mesh, STEEL, [a, _cut(kind, mesh, order), b], axes))


def _halves(kind: str, order):
    """The two halves meshed alone (faces matching node for node), joined through the cut."""
    left, right = _bar(0.0, 0.5 * LENGTH, 4), _bar(0.5 * LENGTH, LENGTH, 4)
    k_left = mirrored_coupled_stiffness(left, STEEL, [_end(left, 0.0), _cut(kind, left, order)], ())
    k_right = mirrored_coupled_stiffness(right, STEEL, [_cut(kind, right, order), _end(right, LENGTH)], ())
    return series_stiffness([k_left, k_right])


def _in_si(K):
    """K with its rotations scaled by the section's half width (entries of one magnitude)."""
    scale = np.concatenate([np.ones(3), np.full(3, HALF)] * 2)
    return K / scale[:, None] / scale[None, :]


def test_the_interfaces_bracket_the_uncut_bar_in_the_energy_order():
    # Kinematic fields on the cut face are constraints on the one-piece mesh, nested as p
    # grows (the rigid motions inside p = 1): rigid >= p1 >= p2 >= p3 >= p4 >= uncut. A
    # distributing coupling of the halves (faces matching node for node) relaxes continuity,
    # the projections nested as p grows: uncut >= d2 >= d1 >= d-rigid. Energy bounds, so
    # every difference is positive semi-definite exactly, up to round-off.
    mesh = _bar(0.0, LENGTH, 8)
    uncut = mirrored_coupled_stiffness(mesh, STEEL, list(_ends(mesh)), ())
    upper = [_one_piece("rigid", None)] + [_one_piece("kinematic", p) for p in (1, 2, 3, 4)]
    lower = [_halves("distributing", p) for p in (2, 1, RIGID)]
    chain = [_in_si(k) for k in upper + [uncut] + lower]
    size = np.abs(_in_si(uncut)).max()
    for stiffer, softer in zip(chain[:-1], chain[1:]):
        eigenvalues = np.linalg.eigvalsh(stiffer - softer)
        # round-off of condensations of a ~3k-DOF system: measured -1.9e-14 of the largest entry; 1e-10
        assert eigenvalues.min() >= -1e-10 * size, eigenvalues.min() / size
    # not a chain of equal matrices: the rigid tie is stiffer than p4 and p4 than the uncut
    # bar on every diagonal entry but the ones p4 already gets (measured: rigid +2.3 % axially,
    # +0.43 / +1.7 / +0.90 % shear, torsion, bending; p4 within 0.003 %)
    gain = (np.diag(upper[0]) - np.diag(upper[-1])) / np.diag(uncut)
    # 0.1 %: a tenth of the smallest measured rigid - p4 (0.43 %, shear)
    assert np.all(gain[:6] > 1e-3), gain
    relax = (np.diag(uncut) - np.diag(lower[-1])) / np.diag(uncut)
    # 0.1 %: the distributing tie on the rigid motions is measured 0.21 to 0.94 % softer off axis
    assert np.all(relax[1:6] > 1e-3), relax


def test_halves_joined_through_a_field_are_the_one_piece_bar_with_that_field():
    # on faces that match node for node, the halves meshed alone, each condensed onto the
    # cut's field coefficients and joined by sharing them, are the one piece with that field
    for kind, order in (("kinematic", 2), ("rigid", None)):
        joined, one_piece = _halves(kind, order), _one_piece(kind, order)
        size = np.abs(_in_si(one_piece)).max()
        # round-off of two condensations of ~1.6k-DOF halves and a Schur complement: measured 5e-15; 1e-10
        np.testing.assert_allclose(_in_si(joined), _in_si(one_piece), rtol=0, atol=1e-10 * size)


def test_the_bar_cut_apart_in_one_mesh_is_its_halves_meshed_alone():
    # split_at_section gives the +x side new nodes on the cut face: distributing couplings of
    # the two faces with shared DOFs (shared_interfaces) are the halves meshed alone and joined
    mesh = _bar(0.0, LENGTH, 8)
    face = _face(mesh, CENTRE[0])
    cut, copies = split_at_section(mesh, face, CENTRE[0])
    assert len(cut.nodes) == len(mesh.nodes) + len(face) and np.array_equal(cut.nodes[copies], mesh.nodes[face])
    sides = [DistributingCoupling(nodes=nodes, reference_point=CENTRE, order=2, scale=HALF) for nodes in (face, copies)]
    a, b = _ends(mesh)
    K = mirrored_coupled_stiffness(cut, STEEL, [a, *sides, b], ())
    one_mesh = condensed_onto_ends(shared_interfaces(K, [6, 18, 18, 6], [(1, 2)]))
    halves = _halves("distributing", 2)
    # round-off of condensations and Schur complements of ~3k DOF (measured 2e-14): 1e-10
    np.testing.assert_allclose(_in_si(one_mesh), _in_si(halves), rtol=0, atol=1e-10 * np.abs(_in_si(halves)).max())


@pytest.mark.parametrize("order, axes", [(2, ()), (RIGID, ()), (2, (1, 2))])
def test_a_piece_held_only_by_distributing_couplings_is_the_bar_cut_apart_twice(order, axes):
    # the middle third [20, 40] mm of the bar held by a distributing coupling on each face
    # floats (its K_ii is singular on the rigid motions): mirrored_coupled_stiffness factorises
    # K_ii + alpha G^T G and takes alpha off the q block. Joined with the two outer thirds it is
    # the bar cut apart at both sections in one mesh with the faces' DOFs shared (the same
    # discrete problem, held through its rigid ends); on the mirror quadrant too
    quadrant = bool(axes)
    thirds = [_bar(LENGTH * k / 3, LENGTH * (k + 1) / 3, 3, quadrant) for k in range(3)]
    xs = [LENGTH / 3, 2 * LENGTH / 3]

    def coupling(mesh, x):
        return DistributingCoupling(nodes=_face(mesh, x), reference_point=np.array([x, 0.0, 0.0]), order=order,
                                    scale=HALF)

    pieces = [mirrored_coupled_stiffness(thirds[0], STEEL, [_end(thirds[0], 0.0), coupling(thirds[0], xs[0])], axes),
              mirrored_coupled_stiffness(thirds[1], STEEL, [coupling(thirds[1], xs[0]), coupling(thirds[1], xs[1])],
                                         axes),
              mirrored_coupled_stiffness(thirds[2], STEEL, [coupling(thirds[2], xs[1]), _end(thirds[2], LENGTH)], axes)]
    middle = pieces[1]
    # the floating piece's null space: a translation projects on each face's field as its
    # component's constant coefficient (the first three DOFs of either field)
    for component in range(3):
        q = np.zeros(n_interface_dofs(order))
        q[component] = 1.0
        motion = np.concatenate([q, q])
        # energy of a translation: round-off against the piece's largest entry, measured <= 3e-14; 1e-9
        assert abs(motion @ middle @ motion) <= 1e-9 * np.abs(middle).max() * (motion @ motion)
    mesh = _bar(0.0, LENGTH, 9, quadrant)
    sides = []
    for x in xs:
        face = _face(mesh, x)
        mesh, copies = split_at_section(mesh, face, x)
        sides += [DistributingCoupling(nodes=nodes, reference_point=np.array([x, 0.0, 0.0]), order=order, scale=HALF)
                  for nodes in (face, copies)]
    n = n_interface_dofs(order)
    K = mirrored_coupled_stiffness(mesh, STEEL, [_end(mesh, 0.0), *sides, _end(mesh, LENGTH)], axes)
    one_mesh = condensed_onto_ends(shared_interfaces(K, [6, n, n, n, n, 6], [(1, 2), (3, 4)]))
    joined = series_stiffness(pieces)
    # round-off of condensations (one of them shifted by alpha ~ the face's stiffness) and Schur
    # complements of ~1-3k DOF: measured <= 1.6e-13; 1e-10
    np.testing.assert_allclose(_in_si(joined), _in_si(one_mesh), rtol=0, atol=1e-10 * np.abs(_in_si(one_mesh)).max())


def test_a_lower_order_field_is_the_higher_order_one_with_its_extra_coefficients_held():
    # the kinematic spaces are nested: the p = 3 condensation restricted to the p = 1
    # coefficients is the p = 1 condensation, and p = 1 restricted to its rigid motions is the
    # rigid tie (one mesh, the same interior: only the masters differ)
    left = _bar(0.0, 0.5 * LENGTH, 4)
    end = _end(left, 0.0)
    k = {order: mirrored_coupled_stiffness(left, STEEL, [end, _cut("kinematic", left, order)], ()) for order in (1, 3)}
    rigid = mirrored_coupled_stiffness(left, STEEL, [end, _cut("rigid", left, None)], ())
    first = 6 + n_interface_dofs(1)
    size = np.abs(k[1]).max()
    # round-off of two direct solves of one system (measured 7e-16 of the largest entry): 1e-10
    np.testing.assert_allclose(k[3][:first, :first], k[1], rtol=0, atol=1e-10 * size)
    points = np.random.default_rng(3).uniform(-HALF, HALF, (20, 3)) * [0, 1, 1] + CENTRE
    R = np.linalg.lstsq(section_modes(points, CENTRE, 1, HALF).reshape(-1, 9),
                        section_modes(points, CENTRE, RIGID, HALF).reshape(-1, 6), rcond=None)[0]
    T = np.zeros((12, first))
    T[:6, :6] = np.eye(6)
    T[6:, 6:] = R.T
    restricted = T @ k[1] @ T.T
    # as above, and R is exact (the rigid motions lie in the linear field): 1e-10
    np.testing.assert_allclose(restricted, rigid, rtol=0, atol=1e-10 * np.abs(rigid).max())


@pytest.mark.parametrize("kind, order", [("kinematic", 3), ("distributing", 2), ("distributing", RIGID)])
def test_the_mirror_part_condenses_to_the_whole_bar(kind, order):
    # a quadrant of the bar (y, z >= 0) condensed class by class with its fields' parities is
    # the whole bar (the quadrant and its mirror images) condensed at once
    quadrant = _bar(0.0, 0.5 * LENGTH, 4, quadrant=True)
    whole = _mirrored(_mirrored(quadrant, 1), 2)
    got, expected = (mirrored_coupled_stiffness(mesh, STEEL, [_end(mesh, 0.0), _cut(kind, mesh, order)], axes)
                     for mesh, axes in ((quadrant, (1, 2)), (whole, ())))
    scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    # two direct solves of the same equations in other elimination orders: measured <= 4e-14; 1e-9
    assert np.max(np.abs(got - expected) / scale) < 1e-9


def test_the_rigid_motions_lie_in_the_linear_field_and_every_field_has_its_parity():
    rng = np.random.default_rng(7)
    points = CENTRE + rng.uniform(-HALF, HALF, (30, 3)) * [0, 1, 1]
    linear = section_modes(points, CENTRE, 1, HALF).reshape(-1, 9)
    rigid = section_modes(points, CENTRE, RIGID, HALF).reshape(-1, 6)
    residual = rigid - linear @ np.linalg.lstsq(linear, rigid, rcond=None)[0]
    assert np.abs(residual).max() < 1e-12 * HALF  # exact up to round-off of a 60 x 9 least squares
    assert [n_interface_dofs(p) for p in (RIGID, 1, 2, 3, 4)] == [6, 9, 18, 30, 45]
    assert polynomial_exponents(2).tolist() == [[0, 0], [1, 0], [0, 1], [2, 0], [1, 1], [0, 2]]
    for order in (RIGID, 1, 2, 3):
        modes = section_modes(points, CENTRE, order, HALF)
        for axis in (1, 2):
            mirror = np.ones(3)
            mirror[axis] = -1.0
            image = section_modes(points * mirror, CENTRE, order, HALF)  # u(M x)
            want = section_mode_parity(order, axis)[None, None, :] * mirror[None, :, None] * modes  # +- M u(x)
            # monomials of coordinates <= 1 after a sign flip: equal up to round-off, 1e-12
            np.testing.assert_allclose(image, want, rtol=0, atol=1e-12)


def test_the_turn_by_pi_about_z_changes_only_the_signs_of_the_field_dofs():
    # a second-half section is the image of a first-half one under x -> L - x, y -> -y (the
    # turn R = diag(-1, -1, 1)): the field q' there, turned, is the field q = signs q' at the
    # image, i.e. Phi(R x + (L, 0, 0)) signs = R Phi(x) at every point of the face, about the
    # image of the centre (section_turn_signs' derivation, checked pointwise, not fitted)
    rng = np.random.default_rng(11)
    points = CENTRE + rng.uniform(-HALF, HALF, (40, 3)) * [0, 1, 1]
    turn = np.diag([-1.0, -1.0, 1.0])
    length = 0.3
    image_centre = turn @ CENTRE + [length, 0.0, 0.0]
    for order in (RIGID, 1, 2, 5, 12):
        modes = section_modes(points, CENTRE, order, HALF)  # (n, 3, n_q) of the twin's face
        image = section_modes(points @ turn.T + [length, 0.0, 0.0], image_centre, order, HALF)
        want = np.einsum("ij,njq->niq", turn, modes)  # R u'(x)
        # Legendre values <= 1 (order 12: sums of ~10 terms of up to ~1e3): round-off, 1e-11
        np.testing.assert_allclose(image * section_turn_signs(order)[None, None, :], want, rtol=0, atol=1e-11)
    # the turned segment: blocks swapped, signs on both; turning twice is the identity
    k = rng.standard_normal((6 + 18, 6 + 18))
    k = k + k.T
    once = turned_segment_stiffness(k, RIGID, 2)
    assert once.shape == (24, 24)
    np.testing.assert_array_equal(once[:18, :18], k[6:, 6:] * np.outer(*[section_turn_signs(2)] * 2))
    np.testing.assert_array_equal(turned_segment_stiffness(once, 2, RIGID), k)
    with pytest.raises(ValueError, match="does not match"):
        turned_segment_stiffness(k, 2, 2)


def test_the_face_mass_matrix_integrates_the_section_s_polynomials():
    # the cut face of the bar (20 x 20 mm, 3 x 3 cells, 18 P2 triangles): int 1 dA = 4 HALF^2,
    # int y^2 dA = 4 HALF^4 / 3, int y^2 z^2 dA = 4 HALF^6 / 9 (P2 interpolates y^2, and the
    # 6-point rule integrates products of P2 functions exactly on straight triangles)
    mesh = _bar(0.0, LENGTH, 2)
    triangles = face_triangles(mesh.tets, _face(mesh, CENTRE[0]))
    assert len(triangles) == 18
    nodes, M = face_mass_matrix(mesh.nodes, triangles)
    y, z = mesh.nodes[nodes, 1], mesh.nodes[nodes, 2]
    one = np.ones(len(nodes))
    integrals = [one @ M @ one, y ** 2 @ M @ one, y ** 2 @ M @ z ** 2]
    # round-off of sums of ~100 products (and the rule's 15-digit weights): 1e-12 relative
    np.testing.assert_allclose(integrals, [4 * HALF ** 2, 4 * HALF ** 4 / 3, 4 * HALF ** 6 / 9], rtol=1e-12)


def test_misuse_is_refused_with_a_message():
    mesh = _bar(0.0, LENGTH, 2)
    face = _face(mesh, 0.0)
    with pytest.raises(ValueError, match="must not be slaves"):
        mirrored_coupled_stiffness(mesh, STEEL, [RigidCoupling(nodes=face, reference_point=np.zeros(3)),
                                                 DistributingCoupling(nodes=face, reference_point=np.zeros(3))], ())
    with pytest.raises(ValueError, match="RigidCoupling is the rigid tie"):
        PolynomialCoupling(nodes=face, reference_point=np.zeros(3), order=0, scale=HALF)
    with pytest.raises(ValueError, match="do not chain"):
        series_stiffness([np.eye(12), np.eye(15)])


@pytest.mark.parametrize("order, axes", [(2, ()), (RIGID, ()), (2, (1, 2)), (1, (2,))])
def test_pinning_a_floating_piece_is_the_shifted_factorisation(order, axes):
    # the middle third of the bar floats between two distributing couplings (above): pinned (k DOFs
    # held, the rigid motions restored on the q side) against session 24's K_ii + alpha G^T G
    quadrant = bool(axes)
    across = np.linspace(0.0, HALF, 3) if quadrant else np.linspace(-HALF, HALF, 4)
    if axes == (2,):  # mirrored about z = 0 only
        middle = grid_tet_mesh(np.linspace(LENGTH / 3, 2 * LENGTH / 3, 4), np.linspace(-HALF, HALF, 4), across)
    else:
        middle = _bar(LENGTH / 3, 2 * LENGTH / 3, 3, quadrant)
    couplings = [DistributingCoupling(nodes=_face(middle, x), reference_point=np.array([x, 0.0, 0.0]), order=order,
                                      scale=HALF) for x in (LENGTH / 3, 2 * LENGTH / 3)]
    pinned = mirrored_coupled_stiffness(middle, STEEL, couplings, axes)
    shifted = mirrored_coupled_stiffness(middle, STEEL, couplings, axes, floating="shift")
    size = np.sqrt(np.outer(np.abs(np.diag(shifted)), np.abs(np.diag(shifted))))
    # the same constrained minimum by two factorisations (shifted by alpha ~ the faces' stiffness, or
    # k DOFs removed): round-off of ~1k-DOF solves and n_q-sized Schur complements, measured <= 1.4e-12
    # of the diagonals' geometric mean; 1e-9
    assert np.all(np.abs(pinned - shifted) <= 1e-9 * size), np.max(np.abs(pinned - shifted) / size)
    assert not np.array_equal(pinned, shifted)  # two routes, not one called twice
