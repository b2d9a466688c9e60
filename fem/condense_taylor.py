"""A mirrored coupled part's condensed stiffness with its first and second derivatives in
parameters that move the part's nodes on one connectivity, from one factorisation per parity
class (issue 26's route to the model's dimension terms without a FEM build per moved chain;
docs/scale.md, "Issue 26, session 40").

``condense.mirrored_coupled_stiffness`` gives, per parity class, the block of M = C^T K^-1 C,
C = [K_im, G^T], and then the class block S(M, K_mm) (``condense.class_block``). Let the part
at parameters r (relative moves, ``part_at(r)``: its mesh on the nominal cells and its
couplings) have K(r), C(r), K_mm(r). With X = K^-1 C at r = 0 and E_p = C_p - K_p X (subscripts:
derivatives in r_p),

    M_p  = C_p^T X + X^T C_p - X^T K_p X
    M_pq = C_pq^T X + X^T C_pq - X^T K_pq X + E_p^T K^-1 E_q + E_q^T K^-1 E_p

(the second from differentiating K X = C twice), where E_p^T K^-1 E_q = Y_p^T Y_q with Y_p = L^-1
P E_p, one forward substitution per parameter on the class's own factors. No new factorisation:
the derivatives of K, C and K_mm are differences of the part assembled at r = +-``step`` e_p
(central, for the first and the diagonal second derivatives) and at +-step (e_p + e_q) (the mixed
ones, from those and the single moves: O(step^2) too), and only their products with X enter, so
a class keeps m x m numbers per assembly. The class block S = A + B^T H^-1 B (A = K_mm - M_kk padded, B = [M_gk, I], H = M_gg)
has the same form, so its derivatives follow with the same two formulas, dense.

The assemblies' differences are those of smooth node motions (``fem.mesh_mapped_chain.
template_grid``: the part meshed on the nominal cells; a parameter that leaves the nodes and
couplings where they were has zero derivatives and no assembly). Errors: the central
differences O(step^2), the rounding of the second differences
~1e-16 / step^2 of the entries (1e-8 at the default step; measured against finite differences
of full condensations in tests/test_fem_condense_taylor.py)."""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass
from typing import Callable

import numpy as np

from flexcal.geometry.params import Material

from .condense import ClassSystem, connectivity_plan, mirror_class_systems

__all__ = ["StiffnessTaylor", "mirrored_coupled_stiffness_taylor", "DERIVATIVE_STEP"]

# the relative move of the assemblies' differences: second differences keep ~1e-16 / step^2
# = 1e-8 of an entry; every difference is O(step^2)
DERIVATIVE_STEP = 1e-4


@dataclass(frozen=True, kw_only=True, eq=False)
class StiffnessTaylor:
    """value (n, n), first (P, n, n), second (P, P, n, n) [SI per unit r]: a condensed stiffness
    and its derivatives in P parameters r; ``at(r)`` its second-order Taylor polynomial."""

    value: np.ndarray
    first: np.ndarray
    second: np.ndarray

    def at(self, r) -> np.ndarray:
        r = np.asarray(r, float)
        if r.shape != (self.first.shape[0],):
            raise ValueError(f"r has shape {r.shape}; expected ({self.first.shape[0]},)")
        return (self.value + np.einsum("p,pij->ij", r, self.first)
                + 0.5 * np.einsum("p,q,pqij->ij", r, r, self.second))


def _add_second_order(second: np.ndarray, halves: list) -> None:
    """E_p^T K^-1 E_q + E_q^T K^-1 E_p added into ``second`` (P, P, m, m) from the halves Y_p
    (Y_p^T Y_q = E_p^T K^-1 E_q; None where E_p = 0), in place."""
    for p, q in itertools.combinations_with_replacement(range(len(halves)), 2):
        if halves[p] is not None and halves[q] is not None:
            product = halves[p].T @ halves[q]
            term = product + product.T  # (p, q)'s and (q, p)'s: one product for both
            second[p, q] += term
            if q != p:
                second[q, p] += term


def _block_taylor(M: np.ndarray, M1: np.ndarray, M2: np.ndarray, K: np.ndarray, K1: np.ndarray, K2: np.ndarray):
    """(value, first, second) of a class block S(M, K_mm) (``condense.class_block``) from those of
    M and K_mm: S = A + B^T W, W = H^-1 B (module docstring)."""
    n_k = K.shape[0]
    n_d = M.shape[0] - n_k
    P = M1.shape[0]

    def parts(Mx, Kx, with_eye):
        A = np.pad(Kx - Mx[:n_k, :n_k], (0, n_d))
        B = np.hstack([Mx[n_k:, :n_k], np.eye(n_d) if with_eye else np.zeros((n_d, n_d))])
        return A, B, Mx[n_k:, n_k:]

    A, B, H = parts(M, K, True)
    if n_d == 0:
        return A, np.array([parts(M1[p], K1[p], False)[0] for p in range(P)]), np.array(
            [[parts(M2[p, q], K2[p, q], False)[0] for q in range(P)] for p in range(P)])
    W = np.linalg.solve(H, B)
    value = A + B.T @ W
    first = np.empty((P, *value.shape))
    E = []
    for p in range(P):
        A_p, B_p, H_p = parts(M1[p], K1[p], False)
        first[p] = A_p + B_p.T @ W + W.T @ B_p - W.T @ H_p @ W
        E.append(B_p - H_p @ W)
    second = np.empty((P, P, *value.shape))
    L = np.linalg.cholesky(H)
    halves = [np.linalg.solve(L, e) for e in E]  # (L^-1 E_p)^T (L^-1 E_q) = E_p^T H^-1 E_q
    for p, q in itertools.product(range(P), repeat=2):
        A_pq, B_pq, H_pq = parts(M2[p, q], K2[p, q], False)
        second[p, q] = A_pq + B_pq.T @ W + W.T @ B_pq - W.T @ H_pq @ W
    _add_second_order(second, halves)
    return value, first, second


def _symmetric_product(upper, X: np.ndarray) -> np.ndarray:
    """K X for K given by its upper triangle (CSR)."""
    return upper @ X + upper.T @ X - upper.diagonal()[:, None] * X


def _diagonal_entries(upper) -> np.ndarray:
    """The positions of the diagonal in the entries of an upper triangle (CSR, sorted, every
    diagonal entry stored: a positive definite K's)."""
    rows = np.repeat(np.arange(upper.shape[0]), np.diff(upper.indptr))
    diagonal = np.flatnonzero(upper.indices == rows)
    if diagonal.size != upper.shape[0]:
        raise ValueError("a class's K has a diagonal entry missing: not positive definite")
    return diagonal


@dataclass(eq=False)
class _ClassState:
    """A class's nominal factors, X = K^-1 C (C order) and M = C^T K^-1 C, its nominal (K, C,
    K_mm) and those of the part moved by +-step along each parameter (for the mixed differences),
    C on ``rows`` only (``_support``), ``diagonal`` the positions of K's diagonal in its upper
    triangle's entries (the pattern every r shares)."""

    factors: object
    X: np.ndarray
    M: np.ndarray
    nominal: tuple
    rows: np.ndarray
    diagonal: np.ndarray
    plus: dict = dataclasses.field(default_factory=dict)
    minus: dict = dataclasses.field(default_factory=dict)


def _support(system: ClassSystem, neighbours: np.ndarray) -> np.ndarray:
    """The rows (positions in the class's kept DOFs, ascending) where its C = [K_im, G^T] can
    be non-zero on this connectivity: the DOFs of ``neighbours`` (a bool per free DOF: its node
    shares an element with a kinematic coupling's node) and the distributing faces' DOFs."""
    return np.union1d(np.flatnonzero(neighbours[system.kept]), np.unique(system.G.indices))


def _rhs_block(system: ClassSystem, rows: np.ndarray) -> np.ndarray:
    """C = [K_im, G^T] on ``rows`` (len(rows), n_k + n_d); ValueError if C has a non-zero
    elsewhere (a moved part whose faces reach other DOFs than the nominal one's)."""
    if not np.isin(np.unique(system.G.indices), rows).all() or np.delete(system.K_im, rows, axis=0).any():
        raise ValueError("a moved part's coupled faces reach other DOFs than the nominal one's: not one connectivity")
    return np.hstack([system.K_im[rows], system.G[:, rows].T.toarray()])


def _same_class(nominal: ClassSystem, other: ClassSystem) -> None:
    """ValueError unless ``other`` has ``nominal``'s DOFs and K_ii pattern (both with stored zeros)."""
    if not (np.array_equal(nominal.both, other.both) and nominal.K_im.shape == other.K_im.shape
            and nominal.G.shape == other.G.shape and np.array_equal(nominal.sub.indptr, other.sub.indptr)
            and np.array_equal(nominal.sub.indices, other.sub.indices)):
        raise ValueError("a moved part's parity class has other DOFs than the nominal one's: the moved mesh is not "
                         "the nominal connectivity with its nodes moved (fem.mesh_mapped_chain.template_grid)")


def mirrored_coupled_stiffness_taylor(part_at: Callable[[np.ndarray], tuple], material: Material,
                                      axes: tuple[int, ...], n_parameters: int, *,
                                      step: float = DERIVATIVE_STEP) -> StiffnessTaylor:
    """The condensed stiffness of ``condense.mirrored_coupled_stiffness`` (its DOF order) at r = 0
    and its first and second derivatives in r (module docstring); ``part_at(r)`` (r (P,)
    relative moves) gives (mesh, couplings) on one connectivity. A part with floating pieces
    (held by distributing couplings alone) is refused. Needs PARDISO (``solve.spd_factors``)."""
    from .assembly import check_mesh
    from .interface import DistributingCoupling
    from .solve import RESIDUAL_LIMIT, spd_factors

    P = int(n_parameters)
    unit = np.eye(P) * step
    mesh0, couplings0 = part_at(np.zeros(P))
    # K_ii with its stored zeros: the pattern every moved part shares (their differences are the
    # values'); the factors take it without them, as ``mirrored_coupled_stiffness`` does
    nominal = mirror_class_systems(mesh0, material, couplings0, axes, drop_zeros=False)
    if nominal.floats:
        raise ValueError("a part with floating pieces (held by distributing couplings alone) has no Taylor "
                         "condensation here: use condense.mirrored_coupled_stiffness")
    plan = connectivity_plan(mesh0, couplings0, nominal)  # the moved parts' index work, done once
    nodes0 = check_mesh(mesh0)[0]
    points0 = [np.asarray(c.reference_point, float) for c in couplings0]

    def moves(r):
        """(mesh, couplings) at r, or None where they are the nominal ones."""
        mesh, couplings = part_at(r)
        same = (np.array_equal(check_mesh(mesh)[0], nodes0) and len(couplings) == len(couplings0)
                and all(np.array_equal(np.asarray(c.reference_point, float), p) for c, p in zip(couplings, points0)))
        return None if same else (mesh, couplings)

    tets = check_mesh(mesh0)[1]
    coupled = np.zeros(len(nodes0), bool)
    for c in couplings0:
        if not isinstance(c, DistributingCoupling):
            coupled[c.nodes] = True
    near = np.zeros(len(nodes0), bool)
    near[np.unique(tets[np.any(coupled[tets], axis=1)])] = True
    neighbours = near[nominal.free // 3]
    states = []
    try:
        for system in nominal.classes:
            without_zeros = system.sub.copy()
            without_zeros.eliminate_zeros()
            factors = spd_factors(without_zeros)
            C = system.rhs()
            Y = factors.half(C)
            X = factors.back(Y)  # K^-1 C, the same bits as a full solve (measured), at half its cost
            if np.linalg.norm(_symmetric_product(factors.upper, X) - C) > RESIDUAL_LIMIT * np.linalg.norm(C):
                raise ValueError("the nominal class's solve failed its residual check: K is singular or nearly so")
            M = Y.T @ Y
            rows = _support(system, neighbours)
            states.append(_ClassState(factors=factors, X=np.ascontiguousarray(X), M=0.5 * (M + M.T), rows=rows,
                                      nominal=(system.sub, _rhs_block(system, rows), system.K_mm),
                                      diagonal=_diagonal_entries(system.sub)))

        def assemble(r):
            """Per class (K's upper triangle with its stored zeros: one pattern for every r; C;
            K_mm) of the part moved by r, None where it is the nominal one."""
            moved = moves(r)
            if moved is None:
                return None
            systems = mirror_class_systems(moved[0], material, moved[1], axes, drop_zeros=False, plan=plan).classes
            for base, system in zip(nominal.classes, systems):
                _same_class(base, system)
            return [(system.sub, _rhs_block(system, state.rows), system.K_mm) for system, state in zip(systems, states)]

        def derivative(state, weights, product=False):
            """(M's term C'^T X + X^T C' - X^T K' X, K_mm', C', K' X if ``product`` else None) of
            the difference sum_i w_i (K_i, C_i, K_mm_i): the matrices differenced entry by entry
            first (their products with X would lose the differences to rounding: X^T K X sits K's
            condition number above them), K on the pattern every r shares. K' = U + U^T with U
            its upper triangle, diagonal halved: X^T K' X = A + A^T with A = X^T (U X), one sparse
            product where K' X takes two (0.07 s against 0.13 s on a 38k-DOF class, 105 columns)."""
            pattern = weights[0][0][0]  # every assembly's (``_same_class``)
            data = sum(w * k.data for (k, _, _), w in weights)
            data[state.diagonal] *= 0.5
            U = type(pattern)((data, pattern.indices, pattern.indptr), shape=pattern.shape)
            UX = U @ state.X
            A = state.X.T @ UX
            C = sum(w * c for (_, c, _), w in weights)  # on the class's rows
            CX = C.T @ state.X[state.rows]
            KX = UX + U.T @ state.X if product else None
            return CX + CX.T - A - A.T, sum(w * m for (_, _, m), w in weights), C, KX

        M1 = [np.zeros((P, s_.M.shape[0], s_.M.shape[0])) for s_ in states]
        M2 = [np.zeros((P, P, s_.M.shape[0], s_.M.shape[0])) for s_ in states]
        K1 = [np.zeros((P, *c.K_mm.shape)) for c in nominal.classes]
        K2 = [np.zeros((P, P, *c.K_mm.shape)) for c in nominal.classes]
        halves = [[None] * P for _ in states]  # per class, per parameter: L^-1 P E_p
        reached = []
        for p in range(P):
            plus, minus = assemble(unit[p]), assemble(-unit[p])
            if plus is None and minus is None:
                continue
            if plus is None or minus is None:
                raise ValueError(f"parameter {p} moves the part on one side of r = 0 only: not a smooth node motion")
            reached.append(p)
            for k, state in enumerate(states):
                up, down = plus[k], minus[k]
                M1[k][p], K1[k][p], C_p, KX_p = derivative(state, [(up, 0.5 / step), (down, -0.5 / step)],
                                                           product=True)
                KX_p *= -1.0  # E_p = C_p - K_p X
                KX_p[state.rows] += C_p
                halves[k][p] = state.factors.half(KX_p)
                M2[k][p, p], K2[k][p, p], _, _ = derivative(state, [(up, step ** -2), (down, step ** -2),
                                                                    (state.nominal, -2.0 * step ** -2)])
                state.plus[p], state.minus[p] = up, down
        for p, q in itertools.combinations(reached, 2):
            # [A(+p+q) + A(-p-q) - A(+-p) - A(+-q) + 2 A(0)] / (2 step^2): O(step^2), as the central
            # differences (the one-sided mixed difference's O(step) was 0.6 % of a tied segment's
            # (a, l) term at 1e-4, which a driving chain's lateral compliance amplified 10x)
            both, both_back = assemble(unit[p] + unit[q]), assemble(-unit[p] - unit[q])
            if both is None or both_back is None:
                raise ValueError(f"parameters {p} and {q} together leave the part as it was, each alone does not")
            w = 0.5 * step ** -2
            for k, state in enumerate(states):
                M2[k][p, q], K2[k][p, q], _, _ = derivative(state, [
                    (both[k], w), (both_back[k], w), (state.plus[p], -w), (state.minus[p], -w), (state.plus[q], -w),
                    (state.minus[q], -w), (state.nominal, 2.0 * w)])
                M2[k][q, p], K2[k][q, p] = M2[k][p, q], K2[k][p, q]
        value = np.zeros((nominal.size, nominal.size))
        first = np.zeros((P, *value.shape))
        second = np.zeros((P, P, *value.shape))
        for k, (state, system) in enumerate(zip(states, nominal.classes)):
            _add_second_order(M2[k], halves[k])
            v, f, s = _block_taylor(state.M, M1[k], M2[k], system.K_mm, K1[k], K2[k])
            both = system.both
            value[np.ix_(both, both)] = nominal.weight * v
            first[:, both[:, None], both[None, :]] = nominal.weight * f
            second[:, :, both[:, None], both[None, :]] = nominal.weight * s
    finally:
        for state in states:
            state.factors.free()
    order = nominal.order
    return StiffnessTaylor(value=value[np.ix_(order, order)], first=first[:, order[:, None], order[None, :]],
                           second=second[:, :, order[:, None], order[None, :]])
