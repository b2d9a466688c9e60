"""The consistent second-order model (docs/model.md 10): the chains' second-order shortening,
their P-delta, their lateral compatibility defect and their own P-delta inside, the frame's
rigid second-order kinematics and the turning lever arms of the chain forces and the weight
solved per point together with the clearance and its play state -- instead of Eq. 4-5's pivot
rows and one Newton step after the clearance (``model.second_order``).

Per chain j, with D_j the 6-vector displacement of its end B in its own frame (``J_j X`` plus
the rigid second-order part ``R_j^T ext_j``, ``ext_j = 1/2 theta x (theta x p_j)``), the chain's
energy is ``U_j = 1/2 e_j^T K_j e_j + 1/2 N_j^2 D_j^T T_j D_j`` in the end strain

    e_j = D_j - u_j e_x + m_j(D_j),  m_j = (D^T S_j D, D^T L_j,y D, ..., D^T L_j,rz D)
    load          N_j = (K_j e_j)_x,   tension N_j (1 + k_j D_j^T T_j D_j)  (the shortening D^T (S + N T) D)
    frame         K_CC X = F_C + sum_j g_j u_j - f2(X)
    f2            sum_j (J_j^T [dU_j/dD_j - K_j (J_j X - u_j e_x)] + [0; L(p_j, F_j)]) - [0; L(r_cg, W)]
    dU/dD         K e + 2 sum_c (K e)_c M_c D + N (D^T T D) K[0, :] + N^2 T D   (M_x = S, M_c = L_c;
                  (K e)_x taken as the tension in the c = x term: the P-delta 2 N S D)
    lever         L(p, F) = (d ext / d theta)^T F = 1/2 (p (theta.F) + (theta.p) F - 2 theta (p.F))

with F_j = R_j (tension, (K_j e_j)_y, (K_j e_j)_z) the chain force and W the weight at r_cg. L_j
(5 x 6 x 6, ``shortening.chain_second_order_forms``) is the lateral part of the chain's BCH
defect (the torsion's couplings with the swing; 12 non-zero entries, passed to the kernel as
sparse terms, ``defect_terms``); T_j (6 x 6) the chain's load form (its elements' P-delta
under the axial load; ``shortening._load_form``). Both come from the candidate's own
elements; neither has a measured correction.

The nut offsets solve Eq. 6-7 with the release ``C + N / k`` and k the nut's stiffness at the point's
equilibrium (``_numba_consistent``: Newton steps with dN/dC measured on the equilibrium).

``S_j`` (6 x 6, chain frame at B) is the candidate's own chain's shortening form from its
elements (``model.shortening.chain_shortening_form``: the flexible chain with exact kinematics
at its element joints) plus a correction measured once at the nominal chains
(``ParameterSpace.chain_shortening``: ``S_measured(P0) - S_elements(P0)``; the calibration layer
measures it on the virtual prototype's chains, ``validation/runs/chain_kinematics.py``), so a
dimension error acts through the element compliances. (Eq. 4-5's pivot form,
``pivot_shortening``, was the base before: it does not follow the leaf thicknesses, and the true
values' dimension errors left a gain error of a few 1e-4, docs/model.md 10.) Energy-consistent:
the P-delta is the gradient of N r, so the parasitic shortening and the geometric stiffness
come from one S.
"""

from __future__ import annotations

import functools

import numpy as np

from .threads import run_split

# [m] two commands this close in every component are one revisited command: 1 pm, ~1e-9 of a
# stroke and far below any actuator's step; a trajectory's way back computed by other arithmetic
# than its way out lands 1e-19 m off (the standard trajectory's A1 and A2 legs) and was not
# recognised as a revisit by an exact comparison (session 43)
REVISIT_TOLERANCE = 1e-12

__all__ = ["pivot_shortening", "shortening_matrices", "defect_terms", "solve_points_consistent"]


def pivot_shortening(end_block, hinge_length, connector, length) -> np.ndarray:
    """Eq. 4-5's shortening form (..., 6, 6) [1/m, 1, m] in the chain frame at B: the local-y
    displacement of the B-side leaf-1 centre (``e + l/2`` from B) over ``2 L_y`` and the local-z
    one of the B-side leaf-2 centre (``e + 3l/2 + c``) over ``2 L_z`` (docs/model.md 5)."""
    e, l, c, length = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (end_block, hinge_length, connector,
                                                                                  length)))
    span_y = length - 2.0 * e - l
    span_z = length - 2.0 * e - 3.0 * l - 2.0 * c
    row_y = np.zeros(e.shape + (6,))
    row_z = np.zeros(e.shape + (6,))
    row_y[..., 1], row_y[..., 5] = 1.0, -(e + 0.5 * l)  # uy - e_y rz
    row_z[..., 2], row_z[..., 4] = 1.0, e + 1.5 * l + c  # uz + e_z ry
    return (row_y[..., :, None] * row_y[..., None, :] / (2.0 * span_y)[..., None, None]
            + row_z[..., :, None] * row_z[..., None, :] / (2.0 * span_z)[..., None, None])


def shortening_matrices(correction, length, hinge_length, width, fillet, thickness_1, thickness_2, *, section,
                        connector_length, end_block_length, material, elements=None, n_threads: int = 1
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S_j (n_c, 6, 6, 6), L_j (n_c, 6, 5, 6, 6), T_j (n_c, 6, 6, 6)): each candidate's chains' own
    shortening form plus the measured correction (6, 6, 6) (or per candidate (n_c, 6, 6, 6)), their
    lateral defect forms and their load forms (``shortening.chain_second_order_forms``; dimensions
    (n_c, 6) [m]). elements: the chains' (element entries, offsets) when the caller has them
    (``chain.chain_entries_and_elements``; the forms then come from them,
    ``shortening.forms_from_elements``, their chains split over ``n_threads``)."""
    from .shortening import chain_second_order_forms, forms_from_elements

    if elements is not None:
        own, lateral, load = forms_from_elements(*elements, n_threads=n_threads)
    else:
        own, lateral, load = chain_second_order_forms(length, hinge_length, width, fillet, thickness_1, thickness_2,
                                                      section=section, connector_length=connector_length,
                                                      end_block_length=end_block_length, material=material)
    return own + np.asarray(correction, dtype=float), lateral, load


def defect_terms(lateral: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lateral defect forms L (n_c, 6, 5, 6, 6) as the kernel's sparse terms: index
    (n_t, 3) int64 rows (c, a, b), a <= b, c in 1..5 the defect's component, and coefficients
    (n_c, 6, n_t) q with ``m_c = sum q d_a d_b`` (off-diagonal pairs folded: q = 2 L[a, b]).
    The terms are the union of the non-zero entries over all candidates and chains (12 of
    the 105 for chains symmetric about their axis, one of them rounding-level: the torsion's
    couplings, and (dy, ry), (dz, rz), (ry, rz) in the torsion's own defect); where that union
    lies inside ``_numba_consistent.SYMMETRIC_DEFECT`` the index is that one, in its order (a
    term no chain has gets zero coefficients), which the kernel writes out term by term."""
    from ._numba_consistent import SYMMETRIC_DEFECT

    lateral = np.asarray(lateral, dtype=float)
    upper = np.triu(np.ones((6, 6), dtype=bool))
    used = np.any(lateral != 0.0, axis=(0, 1)) & upper  # (5, 6, 6)
    symmetric = np.zeros_like(used)
    symmetric[SYMMETRIC_DEFECT[:, 0] - 1, SYMMETRIC_DEFECT[:, 1], SYMMETRIC_DEFECT[:, 2]] = True
    if not np.any(used & ~symmetric):
        c, a, b = SYMMETRIC_DEFECT[:, 0] - 1, SYMMETRIC_DEFECT[:, 1], SYMMETRIC_DEFECT[:, 2]
    else:
        c, a, b = np.nonzero(used)
    index = np.stack([c + 1, a, b], axis=1).astype(np.int64)
    coefficients = lateral[:, :, c, a, b] * np.where(a == b, 1.0, 2.0)
    return index, np.ascontiguousarray(coefficients)


def pack_chains(m, n_threads: int = 1) -> np.ndarray:
    """The kernel's per-chain matrices (n_c, 6, N_PACK, WIDTH) (``_numba_consistent``'s row
    layout): each 6 x 6 matrix as its columns (or rows) padded with zeros to 8 entries, so that
    the kernel's products are sums of 8-wide rows (``_numba_consistent.fill_pack``)."""
    from . import _numba_consistent as nc

    pack = np.zeros((m.n_candidates, 6, nc.N_PACK, nc.WIDTH))
    c = np.ascontiguousarray
    parts = (c(m.frame_transform), c(m.rotation), c(m.shortening), c(m.chain_stiffness), c(m.load_shortening),
             c(m.axial_gain))
    run_split(lambda first, stop: nc.fill_pack(*parts, first, stop, pack, False, 0), m.n_candidates, n_threads)
    return pack


def lane_rows(m, defect: np.ndarray, compliance: np.ndarray, wrench: np.ndarray, n_threads: int = 1) -> np.ndarray:
    """The same entries for ``consistent_native``'s map, the chains as lanes: (n_c, n_rows, 8),
    row ``row * WIDTH + col`` holding ``pack_chains``' [chain, row, col] in lane ``chain`` (lanes
    6, 7 zero), then the rows of ``_consistent_map.c``: point_b (3), the axial stiffness (1), the
    frame's gain columns G[:, j] (6), compliance columns C[:, k] (6; ``compliance`` (n_c, 6, 6)) and
    wrench (1; (n_c, 6)) with the pose's components as lanes, and the lateral defect's
    coefficients ``defect`` (n_c, 6, n_t) (n_t rows); zero rows after them up to a multiple of
    WIDTH (``_numba_consistent.fill_lanes``)."""
    from . import _numba_consistent as nc

    n_c, n_rows = m.n_candidates, lane_row_count(defect.shape[2])
    rows4 = np.empty((n_c, n_rows // nc.WIDTH, nc.WIDTH, 8))
    rows = rows4.reshape(n_c, n_rows, 8)
    c = np.ascontiguousarray
    parts = (c(m.frame_transform), c(m.rotation), c(m.shortening), c(m.chain_stiffness), c(m.load_shortening),
             c(m.axial_gain), c(m.point_b), c(m.axial_stiffness), c(compliance), c(wrench), c(defect))
    run_split(lambda first, stop: nc.fill_lanes(*parts, first, stop, rows4, rows, 0), n_c, n_threads)
    return rows


def lane_row_count(n_terms: int) -> int:
    """The lane rows of one candidate (``lane_rows``) for ``n_terms`` defect terms: the pack's
    N_PACK x WIDTH, then 17 + n_terms, padded to a multiple of WIDTH."""
    from . import _numba_consistent as nc

    return (nc.N_PACK + -(-(17 + n_terms) // nc.WIDTH)) * nc.WIDTH


@functools.cache
def _block_masks() -> tuple[np.ndarray, np.ndarray]:
    """(6, 6) masks of the entries that can be non-zero: a chain stiffness's (``hinge.ENTRY_INDEX``'s
    entries and their transposes: ux, rx, (uy, rz), (uz, ry)) and a load form's (the lateral rows
    and columns ``_numba_shortening.LATERAL``)."""
    from ._numba_shortening import LATERAL
    from .hinge import ENTRY_INDEX

    stiffness = np.zeros((6, 6), dtype=bool)
    for i, j in ENTRY_INDEX.values():
        stiffness[i, j] = stiffness[j, i] = True
    lateral = np.zeros((6, 6), dtype=bool)
    lateral[np.ix_(LATERAL, LATERAL)] = True
    return stiffness, lateral


def lanes_apply(m) -> bool:
    """Whether ``_consistent_map.c``'s map, which skips their zeros, applies to these matrices: every
    chain stiffness on its blocks, every transform's rotation rows free of the frame's translation,
    every load form on its lateral rows and columns (``_block_masks``; all three hold by
    construction: ``chain.stiffness_from_entries``, the rigid transport, ``shortening``'s load form)."""
    stiffness, lateral = _block_masks()
    return bool(np.all(m.chain_stiffness[..., ~stiffness] == 0.0)
                and np.all(m.frame_transform[..., 3:, :3] == 0.0)
                and np.all(m.load_shortening[..., ~lateral] == 0.0))


def revisits(inputs: np.ndarray) -> np.ndarray:
    """(n_p,) int64: for each point the latest earlier point with the same command to
    ``REVISIT_TOLERANCE`` in every component (-1 if none); the kernel starts there, moved by the
    linear response to the difference, when the nut offsets are the same too (a leg's way back).
    Remembered for the last few trajectories (a calibration calls the model on one trajectory
    thousands of times)."""
    inputs = np.ascontiguousarray(inputs, dtype=float)
    return _revisits(inputs.tobytes(), inputs.shape).copy()


@functools.lru_cache(maxsize=8)
def _revisits(data: bytes, shape: tuple[int, ...]) -> np.ndarray:
    from scipy.spatial import cKDTree

    inputs = np.frombuffer(data, dtype=float).reshape(shape)
    out = np.full(shape[0], -1, dtype=np.int64)
    for p, near in enumerate(cKDTree(inputs).query_ball_point(inputs, r=REVISIT_TOLERANCE, p=np.inf)):
        earlier = [q for q in near if q < p]
        out[p] = max(earlier, default=-1)
    return out


def solve_points_consistent(matrices, inputs: np.ndarray, *, clearance: bool, tol: float, max_iter: int,
                            divergence: float, state_tolerance: float, n_threads: int = 1,
                            revisit: bool = True, reuse_rates: bool = True,
                            written_out: bool = True, native: bool | None = None) -> dict[str, np.ndarray]:
    """Run the compiled consistent kernel; same outputs as ``kernel.solve_points_compiled``
    (force_only clearance; ``tol`` [m, rad] on the pose update per point). ``revisit=False``
    starts no point from an earlier one with the same command (``revisits``; for the tests);
    ``reuse_rates=False`` probes every nut off its flank at every Newton step on the offsets, a
    point's loose first one too, instead of taking the previous point's tight rates there (the
    code before session 19; for the tests). ``written_out=False`` sums the lateral defect's terms
    in the loop over their index even where they are ``SYMMETRIC_DEFECT``'s (the code before
    session 21; for the tests). ``native``: the map by ``consistent_native``'s lane copy (None: where
    the C extension is built and ``lanes_apply``); False runs numba's ``_terms`` (the reference; for
    the tests)."""
    import numba

    from . import _numba_consistent, consistent_native
    from .kernel import _FACES
    from .parameters import DRIVING

    m = matrices
    n_c, n_p = m.n_candidates, inputs.shape[0]
    c = np.ascontiguousarray
    out = {"pose": np.empty((n_c, n_p, 6)), "loads": np.empty((n_c, n_p, 6)), "clearance": np.empty((n_c, n_p, 3)),
           "release": np.empty((n_c, n_p, 3)), "parasitic": np.empty((n_c, n_p, 6)),
           "states": np.empty((n_c, n_p, 3), dtype=np.int8), "point_class": np.empty((n_c, n_p), dtype=np.int8),
           "codes": np.empty((n_c, n_p), dtype=np.int64), "iterations": np.empty((n_c, n_p), dtype=np.int64)}
    compliance = np.linalg.inv(m.frame_stiffness)
    wrench = np.einsum("cab,cb->ca", m.frame_stiffness, m.gravity_pose)
    seen = revisits(inputs) if revisit else np.full(inputs.shape[0], -1, dtype=np.int64)
    defect_index, defect = defect_terms(m.lateral_defect)
    symmetric = written_out and np.array_equal(defect_index, _numba_consistent.SYMMETRIC_DEFECT)
    if native is not False:  # the C copy where it is built and applies (each checked once per call)
        applies = consistent_native.AVAILABLE and lanes_apply(m)
        if native and not consistent_native.AVAILABLE:
            raise RuntimeError("flexcal.model._consistent_map is not built (no C compiler when flexcal was installed)")
        if native and not applies:
            raise ValueError("the C map skips the zero entries of K, J and T (consistent.lanes_apply); these "
                             "matrices have others: use native=False")
        native = applies
    # the C copy's lane rows are filled per candidate inside the kernel from the pack's sources
    pack = np.zeros((0, 6, _numba_consistent.N_PACK, _numba_consistent.WIDTH)) if native else pack_chains(m, n_threads)
    arguments = (
        c(compliance), c(wrench), c(m.axial_gain), c(m.axial_stiffness), pack, bool(native),
        lane_row_count(defect.shape[2]), c(m.frame_transform), c(m.rotation), c(m.shortening), c(m.chain_stiffness),
        c(m.load_shortening), c(m.point_b), defect_index, defect, bool(symmetric), c(m.payload),
        c(m.coupling[:, DRIVING][:, :, DRIVING]), c(m.mu), c(m.clearance),
        c(m.initial_position), c(m.nut_stiffness), c(np.maximum(m.breakaway_band, 0.0)),
        bool(clearance and np.all(m.breakaway_band >= 0)), c(inputs, dtype=float), seen, bool(clearance), float(tol),
        int(max_iter), float(divergence), _FACES, float(state_tolerance), c(m.input_gain), bool(reuse_rates),
        out["pose"], out["loads"], out["clearance"],
        out["release"], out["parasitic"], out["states"], out["point_class"], out["codes"], out["iterations"])
    # the candidates in contiguous shares, one compiled call per thread (the kernel holds no GIL);
    # a candidate's bits do not depend on its share (docs/scale.md "Issue 26, session 38")
    run_split(lambda first, stop: _numba_consistent.solve(first, stop, *arguments), n_c,
              min(int(n_threads), numba.config.NUMBA_NUM_THREADS))
    return out
