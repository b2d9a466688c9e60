"""Quadratic (10-node) tetrahedra for 3-D linear elasticity.

Node order (VTK_QUADRATIC_TETRA): corners 0-3, then the mid-edge nodes of the edges
01, 12, 02, 03, 13, 23. Reference tetrahedron: corners (0,0,0), (1,0,0), (0,1,0),
(0,0,1); barycentric coordinates ``L0 = 1 - xi - eta - zeta, L1 = xi, L2 = eta,
L3 = zeta``. Shape functions: corners ``L_i (2 L_i - 1)``, edges ``4 L_i L_j``.

Geometry is isoparametric: a tet whose mid-edge nodes sit off the straight edges (the
mesher may project them onto curved surfaces) is mapped by the same quadratic shape
functions. Quadrature:

* straight-sided (affine) tets: the 4-point rule of degree 2, exact for the stiffness
  integrand (products of two linear gradients times a constant Jacobian);
* curved tets: the 14-point rule of degree 5 (positive weights). The integrand is then
  rational, so no rule is exact, but ``grad N * det J = adj(J)^T grad_xi N`` is a
  polynomial of degree 3, so the constant-strain patch test still passes to round-off.

DOF order inside an element: ``3 * local_node + component`` (x, y, z), matching the
global ``3 * node + component``. Voigt order for stress and strain:
``xx, yy, zz, yz, xz, xy`` with engineering shear strains.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from flexcal.geometry.params import Material

__all__ = [
    "EDGES",
    "REFERENCE_NODES",
    "InvalidElementError",
    "QuadratureRule",
    "TET_4POINT",
    "TET_14POINT",
    "shape_functions",
    "shape_gradients",
    "elasticity_matrix",
    "lame_parameters",
    "strain_displacement",
    "jacobians",
    "affine_elements",
    "element_stiffness",
    "element_stiffness_blocks",
    "element_volumes",
    "element_strain_at_nodes",
    "voigt_strain",
]

EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
"""(6, 2) corner pairs of the mid-edge nodes 4..9."""

_CORNERS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
REFERENCE_NODES = np.vstack([_CORNERS, 0.5 * (_CORNERS[EDGES[:, 0]] + _CORNERS[EDGES[:, 1]])])
"""(10, 3) reference coordinates of the ten nodes."""

# d L_k / d(xi, eta, zeta), k = 0..3
_DL = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True, kw_only=True)
class QuadratureRule:
    """Quadrature on the reference tet: points (n_q, 3), weights (n_q,) summing to 1/6
    (the reference volume); ``degree``: polynomials up to this degree are exact."""

    points: np.ndarray
    weights: np.ndarray
    degree: int

    def __post_init__(self) -> None:
        if self.points.shape != (self.weights.size, 3):
            raise ValueError(f"points {self.points.shape} must be (n_q, 3) with n_q = {self.weights.size}")


def _symmetric_rule(groups: list[tuple[str, float, float]], degree: int) -> QuadratureRule:
    """Build a rule from symmetry orbits: ("a", a, w) -> 4 points (a, a, a, 1-3a);
    ("b", b, w) -> 6 points with two barycentric coordinates b and two 1/2 - b."""
    bary, weights = [], []
    for kind, value, weight in groups:
        if kind == "a":
            for k in range(4):
                point = [value] * 4
                point[k] = 1.0 - 3.0 * value
                bary.append(point)
                weights.append(weight)
        else:
            for i, j in itertools.combinations(range(4), 2):
                point = [0.5 - value] * 4
                point[i] = point[j] = value
                bary.append(point)
                weights.append(weight)
    return QuadratureRule(points=np.array(bary)[:, 1:].copy(), weights=np.array(weights), degree=degree)


TET_4POINT = _symmetric_rule([("a", (5.0 - 5.0**0.5) / 20.0, 1.0 / 24.0)], degree=2)
"""4 points, degree 2 (Hammer-Marlowe-Stroud)."""

TET_14POINT = _symmetric_rule(
    [
        ("a", 0.31088591926330060980, 0.018781320953002641800),
        ("a", 0.092735250310891226402, 0.012248840519393658257),
        ("b", 0.045503704125649649492, 0.0070910034628469110730),
    ],
    degree=5,
)
"""14 points, degree 5, all weights positive (Walkington's rule; checked on monomials
in tests/test_fem_elements.py)."""


def _barycentric(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, float)
    return np.concatenate([1.0 - points.sum(axis=-1, keepdims=True), points], axis=-1)


def shape_functions(points: np.ndarray) -> np.ndarray:
    """P2 shape functions at reference points (..., 3) -> (..., 10)."""
    L = _barycentric(points)
    corners = L * (2.0 * L - 1.0)
    edges = 4.0 * L[..., EDGES[:, 0]] * L[..., EDGES[:, 1]]
    return np.concatenate([corners, edges], axis=-1)


def shape_gradients(points: np.ndarray) -> np.ndarray:
    """Reference gradients d N_a / d(xi, eta, zeta) at points (..., 3) -> (..., 10, 3)."""
    L = _barycentric(points)[..., :, None]  # (..., 4, 1)
    corners = (4.0 * L - 1.0) * _DL
    i, j = EDGES[:, 0], EDGES[:, 1]
    edges = 4.0 * (L[..., j, :] * _DL[i] + L[..., i, :] * _DL[j])
    return np.concatenate([corners, edges], axis=-2)


def lame_parameters(material: Material) -> tuple[float, float]:
    """(lambda, mu) [Pa] of an isotropic material."""
    E, nu = material.youngs_modulus, material.poisson_ratio
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))


def elasticity_matrix(material: Material) -> np.ndarray:
    """Isotropic elasticity matrix D (6, 6) [Pa], Voigt order xx, yy, zz, yz, xz, xy,
    engineering shear strains: sigma = D @ epsilon."""
    lam, mu = lame_parameters(material)
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(3), np.arange(3)] += 2.0 * mu
    D[np.arange(3, 6), np.arange(3, 6)] = mu
    return D


def strain_displacement(gradients: np.ndarray) -> np.ndarray:
    """Strain-displacement matrix B (..., 6, 30) from physical gradients (..., 10, 3) [1/m]:
    epsilon (Voigt, engineering shear) = B @ u_e with u_e ordered 3 * node + component."""
    g = np.asarray(gradients)
    B = np.zeros(g.shape[:-2] + (6, 10, 3))
    for row, (i, j) in enumerate([(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]):
        B[..., row, :, i] += g[..., :, j]
        if i != j:
            B[..., row, :, j] += g[..., :, i]
    return B.reshape(g.shape[:-2] + (6, 30))


def jacobians(coords: np.ndarray, reference_gradients: np.ndarray) -> np.ndarray:
    """Jacobians J[e, q, i, j] = d x_i / d xi_j (n_el, n_q, 3, 3) [m] of elements with node
    coordinates (n_el, 10, 3) [m] at points with reference gradients (n_q, 10, 3)."""
    return np.einsum("eai,qaj->eqij", coords, reference_gradients, optimize=True)


def affine_elements(coords: np.ndarray, relative_tolerance: float = 1e-9) -> np.ndarray:
    """(n_el,) bool: True where every mid-edge node lies at its edge's midpoint within
    ``relative_tolerance`` times the element's longest corner edge (straight-sided tet)."""
    coords = np.asarray(coords, float)
    midpoints = 0.5 * (coords[:, EDGES[:, 0]] + coords[:, EDGES[:, 1]])
    edge_lengths = np.linalg.norm(coords[:, EDGES[:, 1]] - coords[:, EDGES[:, 0]], axis=-1)
    offset = np.linalg.norm(coords[:, 4:] - midpoints, axis=-1).max(axis=1)
    return offset <= relative_tolerance * edge_lengths.max(axis=1)


class InvalidElementError(ValueError):
    """Tets with a non-positive Jacobian; ``elements`` holds their indices (n_bad,)."""

    def __init__(self, elements: np.ndarray):
        self.elements = np.asarray(elements)
        super().__init__(
            f"{self.elements.size} tet(s) have a non-positive Jacobian (first: tet {self.elements[0]}): "
            "the tet is inverted (reorder its corners to give a positive volume) or its mid-edge "
            "nodes are moved so far that the quadratic map folds (refine the mesh near curved surfaces)"
        )


def _inverse_and_det(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse (..., 3, 3) and determinant (...) of 3x3 matrices by the adjugate
    (vectorized closed form; LAPACK's batched inv costs ~15x more on 3x3 blocks)."""
    adj = np.empty_like(J)
    adj[..., 0, 0] = J[..., 1, 1] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 1]
    adj[..., 0, 1] = J[..., 0, 2] * J[..., 2, 1] - J[..., 0, 1] * J[..., 2, 2]
    adj[..., 0, 2] = J[..., 0, 1] * J[..., 1, 2] - J[..., 0, 2] * J[..., 1, 1]
    adj[..., 1, 0] = J[..., 1, 2] * J[..., 2, 0] - J[..., 1, 0] * J[..., 2, 2]
    adj[..., 1, 1] = J[..., 0, 0] * J[..., 2, 2] - J[..., 0, 2] * J[..., 2, 0]
    adj[..., 1, 2] = J[..., 0, 2] * J[..., 1, 0] - J[..., 0, 0] * J[..., 1, 2]
    adj[..., 2, 0] = J[..., 1, 0] * J[..., 2, 1] - J[..., 1, 1] * J[..., 2, 0]
    adj[..., 2, 1] = J[..., 0, 1] * J[..., 2, 0] - J[..., 0, 0] * J[..., 2, 1]
    adj[..., 2, 2] = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    det = J[..., 0, 0] * adj[..., 0, 0] + J[..., 0, 1] * adj[..., 1, 0] + J[..., 0, 2] * adj[..., 2, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = adj / det[..., None, None]
    return inverse, det


def _physical_gradients(coords: np.ndarray, rule: QuadratureRule) -> tuple[np.ndarray, np.ndarray]:
    """Physical gradients (n_el, n_q, 10, 3) [1/m] and det J (n_el, n_q) [m^3]; raises
    ``InvalidElementError`` (a ``ValueError``) for elements whose Jacobian is not positive
    at a quadrature point."""
    dN = shape_gradients(rule.points)  # (q, 10, 3)
    J = jacobians(coords, dN)
    inverse, det = _inverse_and_det(J)
    bad = np.flatnonzero((~(det > 0.0)).any(axis=1))
    if bad.size:
        raise InvalidElementError(bad)
    # grad_x N = grad_xi N @ J^-1
    G = np.matmul(dN[None], inverse)
    return G, det


def _stiffness_from_gradients(G: np.ndarray, weights: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """K_e in component-major layout (n_el, 3, 10, 3, 10), index [e, i, a, j, b], from
    gradients (n_el, n_q, 10, 3) and weights det J * w_q (n_el, n_q).

    K[(a,i),(b,j)] = int lam dN_a/dx_i dN_b/dx_j + mu dN_a/dx_j dN_b/dx_i
                     + mu delta_ij grad N_a . grad N_b
    (the isotropic form of B^T D B, checked against it in the tests). The component-major
    layout keeps the i <-> j swap of the second term a copy of contiguous 10-blocks."""
    n_el, n_q = weights.shape
    flat = G.transpose(0, 1, 3, 2).reshape(n_el, n_q, 30)  # column i * 10 + a
    S = np.matmul((flat * weights[:, :, None]).transpose(0, 2, 1), flat).reshape(n_el, 3, 10, 3, 10)
    K = S.transpose(0, 3, 2, 1, 4) * mu  # [e, i, a, j, b] = S[e, j, a, i, b]
    K += lam * S
    trace = mu * (S[:, 0, :, 0] + S[:, 1, :, 1] + S[:, 2, :, 2])
    for i in range(3):
        K[:, i, :, i] += trace
    return K


def element_stiffness_blocks(
    coords: np.ndarray,
    material: Material,
    rule: QuadratureRule | None = None,
) -> np.ndarray:
    """Element stiffness in component-major layout (n_el, 3, 10, 3, 10) [N/m]:
    ``K[e, i, a, j, b]`` couples component i of node a with component j of node b.
    Same arguments as ``element_stiffness``; the layout assembly uses."""
    coords = np.asarray(coords, float)
    if coords.ndim != 3 or coords.shape[1:] != (10, 3):
        raise ValueError(f"coords has shape {coords.shape}; expected (n_el, 10, 3)")
    lam, mu = lame_parameters(material)
    K = np.empty((coords.shape[0], 3, 10, 3, 10))
    if rule is None:
        affine = affine_elements(coords)
        groups = [(np.flatnonzero(affine), TET_4POINT), (np.flatnonzero(~affine), TET_14POINT)]
    else:
        groups = [(np.arange(coords.shape[0]), rule)]
    for index, group_rule in groups:
        if index.size == 0:
            continue
        try:
            G, det = _physical_gradients(coords[index], group_rule)
        except InvalidElementError as error:
            raise InvalidElementError(index[error.elements]) from None
        K[index] = _stiffness_from_gradients(G, det * group_rule.weights, lam, mu)
    return K


def element_stiffness(
    coords: np.ndarray,
    material: Material,
    rule: QuadratureRule | None = None,
) -> np.ndarray:
    """Element stiffness matrices K_e (n_el, 30, 30) [N/m] of P2 tets, DOF order
    3 * node + component.

    coords (n_el, 10, 3) [m] in VTK node order. ``rule=None`` picks per element: the
    4-point rule for straight-sided tets (exact), the 14-point rule for curved ones;
    a given rule is used for all. Vectorized over elements (no Python loop)."""
    K = element_stiffness_blocks(coords, material, rule)
    return K.transpose(0, 2, 1, 4, 3).reshape(K.shape[0], 30, 30)


def element_volumes(coords: np.ndarray) -> np.ndarray:
    """Volumes (n_el,) [m^3] of (possibly curved) P2 tets with coords (n_el, 10, 3) [m]
    (14-point rule: exact, det J is a cubic polynomial)."""
    coords = np.asarray(coords, float)
    det = np.linalg.det(jacobians(coords, shape_gradients(TET_14POINT.points)))
    return det @ TET_14POINT.weights


def element_strain_at_nodes(coords: np.ndarray, displacements: np.ndarray) -> np.ndarray:
    """Strain (Voigt, engineering shear) at the ten nodes of each element,
    (n_el, 10, 6) [-], from coords (n_el, 10, 3) [m] and element nodal displacements
    (*batch, n_el, 10, 3) [m] -> (*batch, n_el, 10, 6). Evaluated inside each element
    (discontinuous across elements; average for a nodal field)."""
    dN = shape_gradients(REFERENCE_NODES)  # (10 points, 10 functions, 3)
    J = jacobians(np.asarray(coords, float), dN)
    inverse, det = _inverse_and_det(J)
    if not (det > 0).all():
        raise ValueError("a tet has a non-positive Jacobian at a node; check the mesh orientation")
    G = np.matmul(dN[None], inverse)  # (e, p, a, i)
    grad_u = np.einsum("...eak,epai->...epki", displacements, G, optimize=True)  # du_k/dx_i
    return voigt_strain(grad_u)


def voigt_strain(grad_u: np.ndarray) -> np.ndarray:
    """Small strain (..., 6) [-], Voigt order xx, yy, zz, yz, xz, xy with engineering shear
    (gamma = 2 epsilon), of displacement gradients grad_u (..., 3, 3), [k, i] = du_k/dx_i."""
    g = grad_u
    return np.stack([g[..., 0, 0], g[..., 1, 1], g[..., 2, 2],
                     g[..., 1, 2] + g[..., 2, 1], g[..., 0, 2] + g[..., 2, 0], g[..., 0, 1] + g[..., 1, 0]], axis=-1)
