"""Interfaces at a cut section, richer than a rigid tie (issue 26, docs/meshing.md "Session
23: how rich the interface at a cut must be").

A chain cut at a cross-section x = x_c into segments meshed alone is joined again through a
few DOFs per cut face. A rigid tie (``flexcal.fem.coupling.RigidCoupling``, 6 DOFs) makes
the face move as one body. The fields here are the natural hierarchy above it: every
displacement component a complete polynomial of order p in the section coordinates
(y, z) = (x - x_c)[1:] / ``scale`` about the section centre x_c:

    p = 1: 3 x {1, y, z}                       9 DOFs (the rigid motions are in it)
    p = 2: 3 x {1, y, z, y^2, y z, z^2}       18
    p = 3: ... y^3, y^2 z, y z^2, z^3          30
    p:     3 (p + 1) (p + 2) / 2

The basis of that space is P_a(y) P_b(z), a + b <= p, P_a the Legendre polynomials (the
same space as the monomials y^a z^b; on |y|, |z| <= 1 far better conditioned at p ~ 10).
DOF order: basis function by basis function (``polynomial_exponents``), each with its ux,
uy, uz. Two
segments' faces share a field by sharing these coefficients (the same centre and scale on
both sides). Two ways to join through them:

- **kinematic** (``PolynomialCoupling``): each face's nodes follow the field,
  ``u_s = Phi(x_s) q``. On faces that match node for node this is a constraint on the
  one-piece mesh, so the joined stiffness is above the one-piece (untied) one in the
  energy (Loewner) order, and falls towards it as p grows (the spaces are nested);
- **distributing** (``DistributingCoupling``, RBE3-like): each face is free; only its L2
  projection on the fields, ``q = (Phi^T M Phi)^-1 Phi^T M u_face`` (M the face's
  consistent P2 mass matrix), is shared. Every one-piece field passes that test, so the
  joined stiffness is below the one-piece one, and rises towards it as p grows.
  ``order="rigid"``: the projection on the six rigid motions (the least-squares rigid
  motion of the face), the classic distributing coupling.

Both bracket the one-piece stiffness exactly (up to round-off) on matching faces. The cut
sections are planes x = const (the chains' sections), so y and z are the mesh's own axes;
that is what ``master_parity`` assumes for a condensation on a mirror part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .coupling import MIRROR_PARITY, RigidCoupling

__all__ = ["RIGID", "series_stiffness", "condensed_onto_ends", "polynomial_exponents", "n_interface_dofs",
           "section_modes", "section_mode_parity", "section_turn_signs", "turned_segment_stiffness",
           "PolynomialCoupling", "DistributingCoupling", "face_triangles", "face_mass_matrix",
           "split_at_section", "shared_interfaces"]

RIGID = "rigid"
"""The ``order`` of the six rigid motions (ux, uy, uz, rx, ry, rz about the centre)."""


def polynomial_exponents(order: int) -> np.ndarray:
    """(n_basis, 2) int: the degrees (a, b) of the basis functions P_a(y) P_b(z) (or the
    monomials y^a z^b) of a complete polynomial of degree <= ``order``, by degree, then by
    falling a."""
    if int(order) != order or order < 0:
        raise ValueError(f"order={order!r} must be an integer >= 0 (or RIGID)")
    return np.array([(d - b, b) for d in range(int(order) + 1) for b in range(d + 1)], dtype=np.int64)


def n_interface_dofs(order) -> int:
    """DOFs of a section field: 6 for ``RIGID``, 3 (p + 1) (p + 2) / 2 for order p."""
    return 6 if order == RIGID else 3 * len(polynomial_exponents(order))


def section_modes(points: np.ndarray, centre: np.ndarray, order, scale: float) -> np.ndarray:
    """(n, 3, n_q): the displacement of ``points`` (n, 3) [m] per unit DOF of the section
    field of ``order`` (``RIGID`` or p) about ``centre`` (3,) [m]: P_a(y) P_b(z) e_i with
    (y, z) = (x - centre)[1:] / ``scale`` [m] for DOF 3 k + i ((a, b) the k-th row of
    ``polynomial_exponents``, P_a Legendre's); ``RIGID``: ``RigidCoupling``'s modes about
    ``centre``."""
    points = np.asarray(points, float).reshape(-1, 3)
    centre = np.asarray(centre, float).reshape(3)
    if order == RIGID:
        return RigidCoupling(nodes=[0], reference_point=centre).slave_modes(points)
    if not scale > 0:
        raise ValueError(f"scale={scale} m must be > 0")
    exponents = polynomial_exponents(order)
    local = (points - centre)[:, 1:] / scale
    in_y, in_z = (np.polynomial.legendre.legvander(local[:, k], int(order)) for k in (0, 1))  # (n, p + 1)
    basis = in_y[:, exponents[:, 0]] * in_z[:, exponents[:, 1]]  # (n, n_basis)
    modes = np.zeros((len(points), 3, 3 * len(exponents)))
    for i in range(3):
        modes[:, i, i::3] = basis
    return modes


def section_mode_parity(order, axis: int) -> np.ndarray:
    """(n_q,) +1 / -1: each DOF's field symmetric (u(Mx) = M u(x)) or antisymmetric under the
    mirror y -> -y (``axis`` 1) or z -> -z (2), the centre on the mirror plane:
    (-1)^(degree in the mirrored coordinate + [component == axis]); ``RIGID``:
    ``MIRROR_PARITY``."""
    if axis not in MIRROR_PARITY:
        raise ValueError(f"axis={axis!r}: mirror axes are 1 (y) and 2 (z)")
    if order == RIGID:
        return MIRROR_PARITY[axis]
    exponent = polynomial_exponents(order)[:, axis - 1]
    component = np.arange(3)
    return ((-1) ** (exponent[:, None] + (component[None, :] == axis))).ravel()


def section_turn_signs(order) -> np.ndarray:
    """(n_q,) +1 / -1: the section field's DOFs under the turn by pi about z (a chain's second
    half is its first half so turned: x -> L - x, y -> -y, z -> z; displacements and rotations
    u -> R u, R = diag(-1, -1, 1), a proper rotation). The field at the turned section is
    q = signs * q' (q' the field at the section it is the image of, about the image of its
    centre, the same ``scale``).

    Derivation (not a fit): the turned face moves as u(y, z) = R u'(-y, z). With
    u' = sum_k,i q'_ki P_a(y / s) P_b(z / s) e_i and P_a(-t) = (-1)^a P_a(t) (Legendre's parity),
    u(y, z) = sum_k,i (-1)^a R_ii q'_ki P_a(y / s) P_b(z / s) e_i, so q_ki = (-1)^a R_ii q'_ki:
    a diagonal sign, no permutation (the basis is a product of one-variable polynomials and
    the turn changes the sign of one variable). ``RIGID``: R on the translations and on the
    rotations (a pseudovector under a proper rotation is a vector). The face's L2 projection
    (``DistributingCoupling``) commutes with the turn (it maps the face and its mass matrix
    onto themselves), so the same signs hold for its DOFs."""
    turn = np.array([-1, -1, 1])
    if order == RIGID:
        return np.concatenate([turn, turn])
    exponent_y = polynomial_exponents(order)[:, 0]
    return ((-1) ** exponent_y[:, None] * turn[None, :]).ravel()


def turned_segment_stiffness(stiffness: np.ndarray, start_order, end_order) -> np.ndarray:
    """(n, n) [SI]: the stiffness of a segment's mirror image (turned by pi about z: the
    second-half segment [L - b, L - a] of a chain whose first-half twin [a, b] has
    ``stiffness`` (n, n) on its start section's DOFs, then its end section's) on the image's
    start DOFs, then its end DOFs. ``start_order``, ``end_order``: the twin's start and end
    sections' field (``RIGID`` or p; a chain end is ``RIGID``). The image's start is the twin's
    end: K = D P stiffness P^T D with P swapping the two blocks and D the
    ``section_turn_signs`` (q = D q' keeps the energy, D^-1 = D). With both ends ``RIGID`` this
    is the prototype's ``mirror_segment_stiffness``, to the bit."""
    stiffness = np.asarray(stiffness, float)
    n_start, n_end = n_interface_dofs(start_order), n_interface_dofs(end_order)
    if stiffness.shape != (n_start + n_end,) * 2:
        raise ValueError(f"stiffness {stiffness.shape} does not match sections of {n_start} and {n_end} DOFs")
    order = np.r_[n_start:n_start + n_end, 0:n_start]
    signs = np.concatenate([section_turn_signs(end_order), section_turn_signs(start_order)])
    return stiffness[np.ix_(order, order)] * np.outer(signs, signs)


@dataclass(frozen=True, kw_only=True, eq=False)
class PolynomialCoupling:
    """Slave nodes (n_s,) int on a section x = const that follow the section field of
    ``order`` p >= 1 (``section_modes``) about ``reference_point`` (3,) [m] with the length
    ``scale`` [m]: a kinematic coupling for ``flexcal.fem.coupling.coupling_map``, its
    masters the field's coefficients [m]."""

    nodes: np.ndarray
    reference_point: np.ndarray
    order: int
    scale: float
    fixed: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "nodes", np.unique(np.asarray(self.nodes, dtype=np.int64)))
        object.__setattr__(self, "reference_point", np.asarray(self.reference_point, float).reshape(3))
        if self.nodes.size == 0:
            raise ValueError("a polynomial coupling needs at least one slave node")
        if self.order == RIGID or int(self.order) != self.order or self.order < 1:
            raise ValueError(f"order={self.order!r} must be an integer >= 1 (RigidCoupling is the rigid tie)")

    def slave_modes(self, points: np.ndarray) -> np.ndarray:
        """(n, 3, n_q) ``section_modes`` of ``points`` (n, 3) [m]."""
        return section_modes(points, self.reference_point, self.order, self.scale)

    def master_parity(self, axis: int) -> np.ndarray:
        return section_mode_parity(self.order, axis)


@dataclass(frozen=True, kw_only=True, eq=False)
class DistributingCoupling:
    """A distributing (RBE3-like) coupling of the face nodes (n_s,) int on a section
    x = const: its n_q master DOFs are the face displacement's L2 projection on the section
    fields of ``order`` (``RIGID`` or p >= 1) about ``reference_point`` (3,) [m]; the face
    nodes stay free (module docstring)."""

    nodes: np.ndarray
    reference_point: np.ndarray
    order: object = RIGID
    scale: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "nodes", np.unique(np.asarray(self.nodes, dtype=np.int64)))
        object.__setattr__(self, "reference_point", np.asarray(self.reference_point, float).reshape(3))
        if self.nodes.size < 3:
            raise ValueError("a distributing coupling needs a face (at least one triangle of nodes)")
        n_interface_dofs(self.order)  # checks the order

    def master_parity(self, axis: int) -> np.ndarray:
        return section_mode_parity(self.order, axis)

    def projection_terms(self, points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(loads (n_s, 3, n_q) = (M Phi) per face node and component, Gram (n_q, n_q) =
        Phi^T M Phi) [m^2 per unit DOF] of the face of the P2 tets ``tets`` (n_e, 10) on
        ``points`` (n_nodes, 3) [m] whose six nodes are all in ``nodes``; q = Gram^-1
        loads^T u_face."""
        rows, mass = face_mass_matrix(points, face_triangles(tets, self.nodes))
        modes = section_modes(points[self.nodes], self.reference_point, self.order, self.scale)
        position = np.searchsorted(self.nodes, rows)
        loads = np.zeros_like(modes)
        loads[position] = (mass @ modes[position].reshape(len(rows), -1)).reshape(len(rows), 3, -1)
        return loads, np.einsum("aik,aiq->kq", modes, loads)


# the four faces of a P2 tet (VTK order): corners, then the mid-edge nodes of their edges
# c0c1, c1c2, c0c2 (tet edges 01, 12, 02, 03, 13, 23 are nodes 4..9)
_TET_FACES = np.array([[0, 1, 2, 4, 5, 6], [0, 1, 3, 4, 8, 7], [1, 2, 3, 5, 9, 8], [0, 2, 3, 6, 9, 7]])


def face_triangles(tets: np.ndarray, face_nodes: np.ndarray) -> np.ndarray:
    """(n_t, 6) int: the P2 triangles (corners, then mid-edge nodes of c0c1, c1c2, c0c2) of the
    tets (n_e, 10) whose six nodes are all in ``face_nodes``, each once (a face between two
    tets counted once)."""
    tets = np.asarray(tets)
    on_face = np.zeros(int(tets.max()) + 1, bool)
    on_face[np.asarray(face_nodes)[np.asarray(face_nodes) <= tets.max()]] = True
    faces = tets[:, _TET_FACES].reshape(-1, 6)
    faces = faces[np.all(on_face[faces], axis=1)]
    _, first = np.unique(np.sort(faces[:, :3], axis=1), axis=0, return_index=True)
    return faces[np.sort(first)]


# Dunavant's 6-point rule of degree 4 on the triangle (barycentric points, weights summing
# to 1): exact for the product of two P2 shape functions on a straight-sided triangle
_A, _B = 0.445948490915965, 0.091576213509771
_TRI_POINTS = np.array([[1 - 2 * _A, _A, _A], [_A, 1 - 2 * _A, _A], [_A, _A, 1 - 2 * _A],
                        [1 - 2 * _B, _B, _B], [_B, 1 - 2 * _B, _B], [_B, _B, 1 - 2 * _B]])
_TRI_WEIGHTS = np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)


def _triangle_shapes(L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P2 triangle shape functions (q, 6) and their derivatives by (L1, L2) (q, 6, 2) at the
    barycentric points L (q, 3) (L0 = 1 - L1 - L2)."""
    l0, l1, l2 = L.T
    N = np.column_stack([l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1),
                         4 * l0 * l1, 4 * l1 * l2, 4 * l0 * l2])
    dN = np.zeros((len(L), 6, 2))
    dN[:, 0] = -(4 * l0 - 1)[:, None]
    dN[:, 1, 0] = 4 * l1 - 1
    dN[:, 2, 1] = 4 * l2 - 1
    dN[:, 3, 0], dN[:, 3, 1] = 4 * (l0 - l1), -4 * l1
    dN[:, 4, 0], dN[:, 4, 1] = 4 * l2, 4 * l1
    dN[:, 5, 0], dN[:, 5, 1] = -4 * l2, 4 * (l0 - l2)
    return N, dN


def face_mass_matrix(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
    """(nodes (n,) int ascending, M (n, n) CSR [m^2]): the consistent mass matrix
    int N_a N_b dA of the P2 triangles (n_t, 6) on ``points`` (n_nodes, 3) [m]
    (isoparametric, in the triangles' own plane), over the nodes they use."""
    triangles = np.asarray(triangles)
    nodes, local = np.unique(triangles, return_inverse=True)
    local = local.reshape(triangles.shape)
    N, dN = _triangle_shapes(_TRI_POINTS)
    x = np.asarray(points, float)[triangles]  # (t, 6, 3)
    tangents = np.einsum("qak,tai->tqki", dN, x)  # (t, q, 2, 3)
    area = 0.5 * np.linalg.norm(np.cross(tangents[:, :, 0], tangents[:, :, 1]), axis=-1)  # (t, q): |J| / 2
    element = np.einsum("tq,q,qa,qb->tab", area, _TRI_WEIGHTS, N, N)
    M = sp.coo_matrix((element.ravel(), (np.repeat(local, 6, axis=1).ravel(), np.tile(local, (1, 6)).ravel())),
                      shape=(len(nodes), len(nodes))).tocsr()  # duplicates summed
    return nodes, M


def series_stiffness(segments) -> np.ndarray:
    """(12, 12) [SI] between the first segment's start and the last one's end of consecutive
    segments joined at their shared interfaces: segment k (n_k + n_(k+1), n_k + n_(k+1)) on its
    start's DOFs then its end's, n_0 = n_last = 6 (the rigid end centres, ux..rz; one frame),
    n_k inferred along the chain (6 for a rigid tie, ``n_interface_dofs`` for a field).
    Assembled on the n + 1 interfaces, the inner ones condensed out (Schur complement)."""
    segments = [np.asarray(k, float) for k in segments]
    sizes = [6]
    for k in segments:
        sizes.append(k.shape[0] - sizes[-1])
    if sizes[-1] != 6 or min(sizes) < 1 or any(k.shape != (k.shape[0],) * 2 for k in segments):
        raise ValueError(f"segment shapes {[k.shape for k in segments]} do not chain from 6 end DOFs to 6")
    starts = np.concatenate([[0], np.cumsum(sizes)])
    K = np.zeros((starts[-1], starts[-1]))
    for k, segment in enumerate(segments):
        K[starts[k]:starts[k + 2], starts[k]:starts[k + 2]] += segment
    return condensed_onto_ends(K)


def condensed_onto_ends(K: np.ndarray) -> np.ndarray:
    """(12, 12) [SI]: K (n, n) condensed onto its first and last six DOFs (Schur complement),
    symmetrised."""
    ends = np.r_[0:6, K.shape[0] - 6:K.shape[0]]
    inner = np.arange(6, K.shape[0] - 6)
    K_ei = K[np.ix_(ends, inner)]
    out = K[np.ix_(ends, ends)] - K_ei @ np.linalg.solve(K[np.ix_(inner, inner)], K_ei.T)
    return 0.5 * (out + out.T)


def split_at_section(mesh, face_nodes: np.ndarray, x: float):
    """(mesh cut apart at the section x [m], the copies (n_s,) of ``face_nodes``): the tets
    on the +x side (corner centroid beyond x) get new nodes in place of the face's, so the
    two sides meet node for node but are no longer joined (for distributing couplings on
    matching faces, whose joined stiffness bounds the uncut mesh's from below)."""
    from .mesh_tets import TetMesh

    nodes, tets = np.asarray(mesh.nodes, float), np.array(mesh.tets)
    face_nodes = np.unique(np.asarray(face_nodes))
    copies = len(nodes) + np.arange(face_nodes.size)
    renumber = np.arange(len(nodes))
    renumber[face_nodes] = copies
    right = nodes[tets[:, :4], 0].mean(axis=1) > x
    tets[right] = renumber[tets[right]]
    return TetMesh(np.vstack([nodes, nodes[face_nodes]]), tets), copies


def shared_interfaces(K: np.ndarray, sizes: list[int], pairs: list[tuple[int, int]]) -> np.ndarray:
    """K (n, n) on consecutive DOF blocks of ``sizes`` with the blocks of each pair (i, j)
    made one (the same DOFs: P^T K P, the second block's rows and columns added onto the
    first's and removed)."""
    starts = np.concatenate([[0], np.cumsum(sizes)])
    target = np.arange(starts[-1])
    for i, j in pairs:
        if sizes[i] != sizes[j]:
            raise ValueError(f"blocks {i} and {j} have {sizes[i]} and {sizes[j]} DOFs; shared blocks must match")
        target[starts[j]:starts[j + 1]] = target[starts[i]:starts[i + 1]]
    kept, merged = np.unique(target, return_inverse=True)
    P = np.zeros((starts[-1], kept.size))
    P[np.arange(starts[-1]), merged] = 1.0
    return P.T @ K @ P
