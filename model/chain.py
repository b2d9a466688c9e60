"""Paper Eq. 1 on a flexure chain: its nine elements in series from the clamped end A to B.

The equation itself lives in ``model.serial`` (``serial_compliance``; on the eight entries,
``quarter_turn`` and ``moved_along_axis``, which the compiled kernel runs too); this module
says what the elements of a chain are.

A flexure chain (geometry/params.py) from A (x = 0) to B (x = L) in its own frame is
``block | leaf1 | connector | leaf2 | strut | leaf2 | connector | leaf1 | block``:
leaf1 thin in local y, leaf2 = leaf1 turned +90 deg about x (thin in local z), blocks,
connectors and strut uniform Timoshenko beams of the square ``section`` (they are not
rigid: the 327 mm x 50 mm strut of a load chain is axially about as compliant as a leaf).
A driving chain adds an axial spring ``1/actuator_stiffness`` (ball screw + coupling) in
series at A.
"""

from __future__ import annotations

import numpy as np

from flexcal.geometry.frames import twist_transform
from flexcal.geometry.params import FlexureChain, Material

from . import kernel
from .hinge import (ENTRY_INDEX, _gauss_legendre, beam_compliance, entries_to_matrix, gauss_node_count,
                    leaf_compliance, segment_entries, shear_coefficient, torsion_constant)
from .profiles import closed_form_of
from .serial import quarter_turn, serial_compliance, serial_entries_along_axis

__all__ = [
    "serial_compliance",
    "hinge_part_compliance",
    "chain_elements",
    "chain_compliance",
    "chain_compliance_matrix",
    "chain_stiffness_matrix",
    "invert_axial_compliance",
    "chain_compliance_entries",
    "chain_entries_and_elements",
    "stiffness_from_entries",
    "LEAF2_ROTATION",
]

# leaf 2 = leaf 1 turned +90 deg about x: element y -> chain z, element z -> chain -y (exact)
LEAF2_ROTATION = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_KINDS = ("block", "leaf1", "connector", "leaf2", "strut", "leaf2", "connector", "leaf1", "block")


def _dimensions(length, hinge_length, width, fillet, thickness_1, thickness_2, end_block_length,
                connector_length):
    """The chain's dimensions broadcast to one batch shape, and its strut length [m];
    ``ValueError`` when a leaf's fillets do not fit it or the hinges and blocks leave no strut."""
    length, l, w, a, t1, t2 = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in
                                                    (length, hinge_length, width, fillet, thickness_1, thickness_2)))
    if np.any(a < 0) or np.any(2.0 * a > l * (1.0 + 1e-12)):
        raise ValueError("leaf fillet a must satisfy 0 <= a <= l/2 (both fillets must fit the segment)")
    strut = length - 2.0 * end_block_length - 4.0 * l - 2.0 * connector_length
    if np.any(strut <= 0):
        raise ValueError("chain length must exceed 2*end_block + 4*hinge_length + 2*connector "
                         "(the strut length came out <= 0); shorten the hinges or lengthen the chain")
    return length, l, w, a, t1, t2, strut


def chain_elements(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section: float,
                   connector_length: float, end_block_length: float, material: Material):
    """The nine elements of a chain from A to B, for ``serial_compliance``.

    length L [m] (A to B), hinge_length l, width w, fillet a, thickness_1 t1, thickness_2 t2
    [m] broadcast over a batch; section, connector_length, end_block_length [m] scalars.
    Returns (compliance (..., 9, 6, 6), rotation (9, 3, 3), loaded-end point (..., 9, 3)).
    """
    length, l, w, a, t1, t2, strut = _dimensions(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                                 end_block_length, connector_length)
    leaves = leaf_compliance(l[..., None], np.stack([t1, t2], axis=-1), w[..., None], a[..., None], material)
    blocks = beam_compliance(np.array([end_block_length, connector_length]), section, section, material)
    strut_c = beam_compliance(strut, section, section, material)
    shape = length.shape
    block_c = np.broadcast_to(blocks[0], shape + (6, 6))
    conn_c = np.broadcast_to(blocks[1], shape + (6, 6))
    by_kind = {"block": block_c, "leaf1": leaves[..., 0, :, :], "connector": conn_c,
               "leaf2": leaves[..., 1, :, :], "strut": strut_c}
    compliance = np.stack([by_kind[k] for k in _KINDS], axis=-3)
    lengths = [end_block_length, l, connector_length, l, strut, l, connector_length, l, end_block_length]
    ends = np.cumsum(np.stack([np.broadcast_to(v, shape) for v in lengths], axis=-1), axis=-1)
    points = np.zeros(shape + (9, 3))
    points[..., 0] = ends
    rotation = np.stack([LEAF2_ROTATION if k == "leaf2" else np.eye(3) for k in _KINDS])
    return compliance, rotation, points


COMPILED_MIN_CHAINS = 256  # batches this large use the compiled kernel (same formulas, tested equal)
_KEYS = tuple(ENTRY_INDEX)  # ux_Fx, uy_Fy, uy_Mz, rz_Mz, uz_Fz, uz_My, ry_My, rx_Mx


def _uniform_entries(length, height, width, material: Material) -> np.ndarray:
    """Entries (8, ...) of a uniform Timoshenko beam (height along y, width along z) at its
    free end: e.g. uy/Fy = L^3/(3 E I_z) + L/(k G A). Equal to ``segment_entries`` with no fillet."""
    e, g = material.youngs_modulus, material.shear_modulus
    kappa = shear_coefficient(material.poisson_ratio)
    length, h, w = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (length, height, width)))
    area = h * w
    ei_z, ei_y = e * w * h**3 / 12.0, e * h * w**3 / 12.0
    shear = length / (kappa * g * area)
    return np.stack([length / (e * area), length**3 / (3.0 * ei_z) + shear, length**2 / (2.0 * ei_z), length / ei_z,
                     length**3 / (3.0 * ei_y) + shear, -(length**2) / (2.0 * ei_y), length / ei_y,
                     length / (g * torsion_constant(h, w))])


def chain_compliance(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section: float,
                     connector_length: float, end_block_length: float, material: Material,
                     actuator_stiffness=None) -> np.ndarray:
    """Compliance (..., 6, 6) at end B of a chain, chain frame, end A clamped (Eq. 1).

    Arguments as in ``chain_compliance_entries``.
    """
    return entries_to_matrix(chain_compliance_entries(
        length, hinge_length, width, fillet, thickness_1, thickness_2, section=section,
        connector_length=connector_length, end_block_length=end_block_length, material=material,
        actuator_stiffness=actuator_stiffness))


def chain_compliance_entries(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section,
                             connector_length, end_block_length, material: Material,
                             actuator_stiffness=None) -> dict[str, np.ndarray]:
    """The eight independent entries (``hinge.ENTRY_INDEX``) of the chain compliance at B.

    Dimensions as in ``chain_elements`` (batch-broadcast, [m]); actuator_stiffness [N/m]
    (scalar or batch, None = no actuator): an axial spring in series at A. Evaluates Eq. 1
    on the eight independent entries (all elements are collinear with x: leaf 2's
    ``serial.quarter_turn``, then ``serial.serial_entries_along_axis``); identical to
    ``serial_compliance(*chain_elements(...))`` to rounding (tests/test_model_chain.py).
    """
    length, l, w, a, t1, t2, strut = _dimensions(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                                 end_block_length, connector_length)
    if length.size >= COMPILED_MIN_CHAINS and kernel.available():
        nodes, weights = _chain_quadrature(a, t1, t2)
        actuator = 0.0 if actuator_stiffness is None else 1.0 / np.asarray(actuator_stiffness, dtype=float)
        out = kernel.chain_entries_compiled(length, l, w, a, t1, t2, section, connector_length, end_block_length,
                                            actuator, material, shear_coefficient(material.poisson_ratio), nodes,
                                            weights)
        return {key: out[..., i] for i, key in enumerate(_KEYS)}
    e, nu = material.youngs_modulus, material.poisson_ratio
    shape = length.shape
    flat = lambda v: np.broadcast_to(v, shape).reshape(-1)  # noqa: E731 - batch as one axis
    leaves = segment_entries(flat(np.maximum(0.5 * l - a, 0.0))[None, :], flat(a)[None, :],
                             np.stack([flat(t1), flat(t2)]), flat(w)[None, :], e, nu)
    leaf = np.stack([leaves[k] for k in _KEYS], axis=1)  # (2 leaves, 8, n)
    leaf2 = np.stack(quarter_turn(leaf[1]))
    block = _uniform_entries(flat(np.asarray(end_block_length, float)), flat(np.asarray(section, float)),
                             flat(np.asarray(section, float)), material)
    connector = _uniform_entries(flat(np.asarray(connector_length, float)), flat(np.asarray(section, float)),
                                 flat(np.asarray(section, float)), material)
    strut_entries = _uniform_entries(flat(strut), flat(np.asarray(section, float)), flat(np.asarray(section, float)),
                                     material)
    by_kind = {"block": block, "leaf1": leaf[0], "connector": connector, "leaf2": leaf2, "strut": strut_entries}
    lengths = {"block": flat(np.asarray(end_block_length, float)), "leaf1": flat(l),
               "connector": flat(np.asarray(connector_length, float)), "leaf2": flat(l), "strut": flat(strut)}
    elements = np.stack([by_kind[k] for k in _KINDS])  # (9, 8, n)
    ends = np.cumsum(np.stack([lengths[k] for k in _KINDS]), axis=0)  # loaded end of each element
    total = serial_entries_along_axis(elements, ends, flat(length))  # output at B
    if actuator_stiffness is not None:
        # an axial spring at A: T = [[I, [r]x], [0, I]] with r along x leaves only C_xx
        total[0] = total[0] + flat(1.0 / np.asarray(actuator_stiffness, dtype=float))
    return {key: total[i].reshape(shape) for i, key in enumerate(_KEYS)}


def _chain_quadrature(a, t1, t2) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights of the compiled chain kernels for a batch of leaves
    (fillets a, thicknesses t1, t2 [m]): enough for its worst arc (``gauss_node_count``)."""
    tau = np.sqrt(np.stack([t1, t2]) / (np.stack([t1, t2]) + 4.0 * a))
    return _gauss_legendre(gauss_node_count(1.0 / tau[np.broadcast_to(a, tau.shape) > 0]))


def chain_entries_and_elements(length, hinge_length, width, fillet, thickness_1, thickness_2, *, section,
                               connector_length, end_block_length, material: Material, n_threads: int = 1
                               ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """``chain_compliance_entries`` (no actuator) and ``shortening``'s element entries of the same
    chains from one pass of the compiled kernel (``_numba_kernels.chain_entries_elements``): the
    entries {key: (...)}, the elements' entries (..., 9, 8) at their loaded ends in the chain's
    axes (A -> B: block, leaf 1, connector, leaf 2 turned, strut, ...; ``hinge.ENTRY_INDEX``
    order) and their offsets (..., 9) [m] (loaded end minus B along x). Needs numba: the
    consistent model's set-up, which runs compiled at every batch size (``assembly``); the chains
    split over ``n_threads``."""
    length, l, w, a, t1, t2, _ = _dimensions(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                             end_block_length, connector_length)
    nodes, weights = _chain_quadrature(a, t1, t2)
    out, elements, offsets = kernel.chain_entries_elements_compiled(
        length, l, w, a, t1, t2, section, connector_length, end_block_length, material,
        shear_coefficient(material.poisson_ratio), nodes, weights, n_threads=n_threads)
    return {key: out[..., i] for i, key in enumerate(_KEYS)}, elements, offsets


def chain_compliance_matrix(chain: FlexureChain, material: Material, actuator_stiffness: float | None = None) -> np.ndarray:
    """(6, 6) compliance at end B of one ``FlexureChain`` (chain frame, A clamped)."""
    return chain_compliance(chain.length, chain.hinge_length, chain.width, chain.fillet, chain.thickness_1,
                            chain.thickness_2, section=chain.section, connector_length=chain.connector_length,
                            end_block_length=chain.end_block_length, material=material,
                            actuator_stiffness=actuator_stiffness)


def stiffness_from_entries(entries: dict[str, np.ndarray]) -> np.ndarray:
    """Inverse (..., 6, 6) of a compliance given by its eight entries (collinear chain).

    Such a compliance is diagonal in ux and rx and has 2x2 blocks (uy, rz) and (uz, ry);
    they are inverted in closed form. Raises ``ValueError`` if it is not positive definite.
    """
    e = entries
    shape = np.broadcast_shapes(*(np.shape(v) for v in e.values()))
    out = np.zeros(shape + (6, 6))
    out[..., 0, 0] = 1.0 / e["ux_Fx"]
    out[..., 3, 3] = 1.0 / e["rx_Mx"]
    dets = []
    for (a, b, c), (i, j) in ((("uy_Fy", "uy_Mz", "rz_Mz"), (1, 5)), (("uz_Fz", "uz_My", "ry_My"), (2, 4))):
        det = e[a] * e[c] - e[b] * e[b]
        dets.append(det)
        out[..., i, i] = e[c] / det
        out[..., j, j] = e[a] / det
        out[..., i, j] = out[..., j, i] = -e[b] / det
    ok = (e["ux_Fx"] > 0) & (e["rx_Mx"] > 0) & (e["uy_Fy"] > 0) & (e["uz_Fz"] > 0) & (dets[0] > 0) & (dets[1] > 0)
    if not np.all(ok):
        raise ValueError("chain compliance is not positive definite; check the chain dimensions (all must be > 0)")
    return out


def invert_axial_compliance(compliance: np.ndarray) -> np.ndarray:
    """Inverse (..., 6, 6) of a compliance of elements collinear with x (``stiffness_from_entries``).

    Raises ``ValueError`` if the matrix has entries outside the collinear pattern (use
    ``np.linalg.inv`` then) or is not positive definite.
    """
    c = np.asarray(compliance, dtype=float)
    mask = np.zeros((6, 6), dtype=bool)
    for i, j in ENTRY_INDEX.values():
        mask[i, j] = mask[j, i] = True
    scale = np.max(np.abs(c), axis=(-2, -1), keepdims=True)
    if np.any(np.abs(np.where(mask, 0.0, c)) > 1e-12 * scale):
        raise ValueError("compliance is not of a chain collinear with x (off-block entries); use np.linalg.inv")
    return stiffness_from_entries({key: c[..., i, j] for key, (i, j) in ENTRY_INDEX.items()})


def chain_stiffness_matrix(chain: FlexureChain, material: Material) -> np.ndarray:
    """(12, 12) stiffness of one chain, DOFs ``[A(6), B(6)]`` in the chain frame.

    A at x = 0, B at x = L, twists ``[ux, uy, uz, rx, ry, rz]`` of each end. With
    ``K = C_B^-1`` and ``W = [[I, -[L e_x]x], [0, I]]`` (rigid map of A's twist to B), the
    strain energy ``1/2 (X_B - W X_A)^T K (X_B - W X_A)`` gives
    ``[[W^T K W, -W^T K], [-K W, K]]``; its null space is the six rigid-body motions.
    """
    k = invert_axial_compliance(chain_compliance_matrix(chain, material))
    w = twist_transform(np.eye(3), np.array([-chain.length, 0.0, 0.0]))  # r = p_A - p_B
    out = np.empty((12, 12))
    out[:6, :6] = w.T @ k @ w
    out[:6, 6:] = -w.T @ k
    out[6:, :6] = -k @ w
    out[6:, 6:] = k
    return out


def hinge_part_compliance(hinge, material: Material) -> np.ndarray:
    """(6, 6) compliance of a whole hinge part at its free-end reference point with its two
    blocks elastic: fixed block, hinge, free block in series (Eq. 1), the blocks as
    Timoshenko beams of the block height x width. ``hinge_compliance_matrix`` takes the
    blocks rigid; an FEM of the part sees them, so this is the like-for-like reference.
    """
    core = closed_form_of(hinge).compliance(hinge, material)
    half, width = 0.5 * hinge.length, hinge.width
    block = beam_compliance(hinge.block_length, hinge.height, width, material)
    end = half + hinge.block_length
    elements = np.stack([block, core, block])
    points = np.array([[-half, 0.0, 0.0], [half, 0.0, 0.0], [end, 0.0, 0.0]])
    rotations = np.broadcast_to(np.eye(3), (3, 3, 3))
    return serial_compliance(elements, rotations, points, np.array([end, 0.0, 0.0]))
