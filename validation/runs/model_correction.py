"""FEM-informed chain compliance for the analytic model (docs/model.md section 7).

The model's chains are closed-form beams (paper Eq. 1 over Euler-Bernoulli hinge
integrals); against the FEM their torsion is 73-81 % too soft and their axial compliance
7-41 % off (docs/model-vs-fem.md). That model-form error, not the optimizer, limits the
Section 3.3 identification on FEM truth. The correction keeps the model's structure and
its dependence on the error sources, and scales each of a chain's eight independent
compliance entries by the ratio measured once at the nominal design:

    C_e(P) = C_e,closed-form(P) * C_e,provider(P0) / C_e,closed-form(P0)

where the provider is the same segment stiffness the virtual prototype is built from
(``flexcal.validation.prototype.segments``), composed along the chain as the prototype's frame
joins it (``twist_end_compliance``): rigidly at the cuts (Eq. 1), or for the tied provider
(``--provider fem``, the default since session 25) through the cut fields, from its K_chain on the five segments' twists.
With the analytic provider the factors are 1 (to the beam-theory rounding); with the FEM provider
they carry the FEM's verdict into every model evaluation at no run-time cost. The corrections
must come from the truth's own provider: the tied chains are 19-23 % softer axially than the
rigidly joined ones, and the consistent model with the rigid corrections against the tied truth
is 16-18 / 13-15 urad RMS off (theta_x / theta_y, table1 seeds 1-3; docs/model.md 7, "Session 25").
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np
import scipy.linalg

from flexcal.geometry.params import FlexureChain
from flexcal.model.chain import chain_compliance_matrix
from flexcal.model.hinge import ENTRY_INDEX
from flexcal.model.parameters import DIMENSION_FIELDS, DIMENSION_SYMBOLS, ParameterSpace

from ..prototype.segments import (StiffnessProvider, chain_slices, end_stiffness, prepare_chains, prepare_provider,
                                  is_tied, same_design, section_nodes, sharing_segments)
from .model_names import DEFAULT_BREAKAWAY_N, MODEL_STIFFNESS, MODELS

__all__ = ["provider_chain_compliance", "twist_end_compliance", "compliance_factors", "compliance_slopes", "slope_provider", "unchanged_slices", "same_design", "corrected_space",
           "model_space", "MODEL_STIFFNESS", "MODELS", "DEFAULT_BREAKAWAY_N", "SLOPE_STEPS", "SLOPE_ELEMENTS_THROUGH",
           "SLOPE_METHODS", "SLOPE_METHOD", "segment_stiffness_slopes", "DERIVATIVE_STEP", "TERM_CHAINS",
           "DEFAULT_TERM_CHAINS", "model_provider", "difference_steps"]


def provider_chain_compliance(chain: FlexureChain, provider: StiffnessProvider) -> np.ndarray:
    """(6, 6) compliance at end B of ``chain`` (A clamped, chain frame) [SI] from a segment
    stiffness provider, the chain as the virtual prototype's frame holds it
    (``twist_end_compliance``): a provider with ``chain_stiffness(chain)`` (the tied one,
    ``tied_chains.tied_fem_provider``: the five segments joined through section fields at the
    cuts) on its K_chain (30, 30); any other on the block diagonal of its five segments' K_jj
    (rigid cuts), which is Eq. 1's sum of each segment's end compliance moved to B."""
    if is_tied(provider):
        return twist_end_compliance(np.asarray(provider.chain_stiffness(chain), dtype=float), section_nodes(chain))
    nodes = section_nodes(chain)
    return _composed_compliance(chain, [provider(chain, float(start), float(end))
                                        for start, end in zip(nodes[:-1], nodes[1:])])


def _composed_compliance(chain: FlexureChain, segments) -> np.ndarray:
    """``provider_chain_compliance`` from the chain's five segment stiffnesses (12, 12) in order,
    joined rigidly at the cuts: K_chain the block diagonal of their K_jj."""
    return twist_end_compliance(scipy.linalg.block_diag(*(end_stiffness(k) for k in segments)), section_nodes(chain))


def twist_end_compliance(twist_stiffness: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """(6, 6) [SI] compliance at the last of ``nodes`` (n + 1,) [m, along x] of n segments in
    series whose deformation twists carry ``twist_stiffness`` (6 n, 6 n) [SI] (energy 1/2 Xi^T K
    Xi, each segment's twist at its end node, chain frame; ``fem.cut_warping.chain_twist_stiffness``),
    the first node clamped, chain frame.

    A wrench f at B loads segment s's end node x_(s+1) with T_s^T f, T_s the twist transfer from
    there to B (``twist_transform``, offset (x_(s+1) - x_B) e_x); the twists Xi = K^-1 T^T f move B
    by T Xi, so C = T K^-1 T^T, T = [T_1 .. T_n] (6, 6 n) (Eq. 1 for coupled segments). With K
    block diagonal (the segments joined rigidly: K_ss their K_jj) it is Eq. 1, sum_s T_s K_ss^-1
    T_s^T. K is solved Jacobi-scaled (its entries span ~1e9 N/m to the leaves' N m/rad) by Cholesky."""
    from flexcal.geometry.frames import twist_transform

    nodes = np.asarray(nodes, dtype=float)
    n = len(nodes) - 1
    stiffness = np.asarray(twist_stiffness, dtype=float)
    if stiffness.shape != (6 * n, 6 * n):
        raise ValueError(f"twist stiffness {stiffness.shape} does not match {n} segments (6 n, 6 n)")
    offsets = np.stack([nodes[1:] - nodes[-1], np.zeros(n), np.zeros(n)], axis=-1)
    transfer = np.concatenate(list(twist_transform(np.broadcast_to(np.eye(3), (n, 3, 3)), offsets)), axis=1)
    root = 1.0 / np.sqrt(np.diag(stiffness))
    scaled = 0.5 * (stiffness + stiffness.T) * root[:, None] * root[None, :]
    try:
        factor = scipy.linalg.cho_factor(scaled)
    except np.linalg.LinAlgError:
        raise ValueError("the chain's twist stiffness is not positive definite; check the provider") from None
    weighted = transfer * root[None, :]
    total = weighted @ scipy.linalg.cho_solve(factor, weighted.T)
    return 0.5 * (total + total.T)


def compliance_factors(space: ParameterSpace, provider: StiffnessProvider) -> np.ndarray:
    """(n_chains, 8) ratios provider / closed form of the eight entries (``ENTRY_INDEX``
    order) at the nominal chains of ``space.mechanism`` (no actuator spring) [-], each chain
    as ``provider_chain_compliance`` composes it (a tied provider's: through its cut fields)."""
    mech = space.mechanism
    rows, done = [], {}
    # one design, one FEM solve (``same_design``: L2 is 1 ulp longer than L1 and L3), as the slopes
    chains = [mech.chains[first].chain for first in same_design(mech.chains)]
    prepare_chains(provider, chains)  # parallel FEM builds
    for key in chains:
        if key not in done:  # identical chains (L1-L3, D1-D3) share their FEM solve
            richer = provider_chain_compliance(key, provider)
            closed = chain_compliance_matrix(key, mech.material)
            done[key] = np.array([richer[i, j] / closed[i, j] for i, j in ENTRY_INDEX.values()])
        rows.append(done[key])
    factors = np.array(rows)
    if not np.all(np.isfinite(factors) & (factors > 0)):
        raise ValueError("the provider's chain compliance has an entry of another sign than the closed form's; "
                         "the segment stiffness is not a valid chain (check the provider)")
    return factors


# Relative step of each dimension for the slopes (central difference, +-step), inside the
# +-10 % the error sources span. The fillet's is 2.5 %: the driving chain's leaf segments at
# fillet x 1.03 (6.18 mm) fail to build (PARDISO error -4 on the mapped mesh, session 14),
# those at x 1.025 and x 0.97 build.
SLOPE_STEPS = {"w": 0.03, "a": 0.025, "l": 0.03, "t1": 0.03, "t2": 0.03}
# The grid of the slopes' builds by default: None, the provider's own (the prototype's 6 cells
# through the thinnest section on the mapped grid). A coarser mapped grid (``elements_through``,
# ``slope_provider``) was measured and rejected (docs/model.md 7, "Slopes on a coarser grid",
# session 15): at 3 through the slopes' CPU drops ~5x and the factors at table1's true
# dimensions move by <= 0.14 % (their error left is 0.11-0.19 %), but the form error on
# table1's `flexcal design` trajectory rises from 0.10 / 0.27 / 0.07 to 0.18 / 0.49 / 0.12 urad
# (4 through: 0.14 / 0.39 / 0.10). Measured again on the tied chains with the quadratic terms
# (session 36: slopes, curvatures and shortening slopes on 4 / 5 through, which would take the
# cold main job's model chains from ~92 to ~30 / ~55 s): the design's form error 0.07 / 0.05 /
# 0.01 urad becomes 0.14 / 0.65 / 0.16 (4) and 0.13 / 0.51 / 0.12 (5), past issue 24's 0.25
# (docs/model.md 11, "Session 36"). The tied provider's ``on_grid`` is tied too.
SLOPE_ELEMENTS_THROUGH: float | None = None


def difference_steps(provider: StiffnessProvider) -> dict[str, float]:
    """The relative steps of the dimension terms' differences with ``provider``: its own
    ``difference_steps`` if it has them (``prototype.tied_taylor``: its moved chains are
    derivatives, taken at small steps), else ``SLOPE_STEPS``."""
    return getattr(provider, "difference_steps", None) or SLOPE_STEPS


def slope_provider(provider: StiffnessProvider, elements_through: float | None = SLOPE_ELEMENTS_THROUGH):
    """The provider the slopes are measured with: a mapped FEM provider (``fem_provider``'s
    ``on_grid``) on ``elements_through`` cells through the thinnest section (its own cache keys);
    any other provider (analytic, fTetWild) or elements_through None: ``provider`` itself."""
    on_grid = getattr(provider, "on_grid", None)
    if elements_through is None or not callable(on_grid) or getattr(provider, "mesher", None) != "mapped":
        return provider
    return on_grid(float(elements_through))


def slope_moves(space: ParameterSpace, steps: dict[str, float] | None = None) -> dict[tuple, FlexureChain]:
    """{(chain index, dimension symbol, sign): the moved chain} of ``compliance_slopes``' builds:
    each chain design's first chain (``same_design``) with one dimension scaled by (1 + sign
    step) (``SLOPE_STEPS`` by default), in the order the builds ask for them."""
    steps = SLOPE_STEPS if steps is None else steps
    mech = space.mechanism
    design = same_design(mech.chains)
    return {(c, symbol, sign): _moved(p.chain, symbol, sign * steps[symbol])
            for c, p in enumerate(mech.chains) if design[c] == c for symbol in DIMENSION_SYMBOLS for sign in (1, -1)}


def unchanged_slices(nominal: FlexureChain, moved: FlexureChain) -> set[tuple[float, float]]:
    """The slices (x_start, x_end) [m] between the section nodes of ``moved`` whose solid is
    that of the same slice of ``nominal`` (same nodes, same pieces: ``flexcal.geometry.exact.pieces``,
    which is all a segment's mesh and end faces are made from), so the segment of ``nominal``
    stands for it, bit for bit (tested). On table1's L1 and D1 at ``SLOPE_STEPS``: the strut when
    w, a, t1 or t2 move, leaf 2's [m1, s0] when t1 moves, leaf 1's [0, m1] when t2 moves (and
    their mirror twins), none when l moves (the nodes move). The tied chains share by the same
    rule through their segments' cache key (``cut_fields.interface_condensation_parts``: the
    pieces), tested to give these slices."""
    from flexcal.geometry.exact import pieces
    from flexcal.geometry.params import ChainSegment

    nodes = section_nodes(moved)
    if moved.length != nominal.length or not np.array_equal(nodes, section_nodes(nominal)):
        return set()
    return {(float(x0), float(x1)) for x0, x1 in zip(nodes[:-1], nodes[1:])
            if pieces(ChainSegment(chain=moved, x_start=float(x0), x_end=float(x1)))
            == pieces(ChainSegment(chain=nominal, x_start=float(x0), x_end=float(x1)))}


def compliance_slopes(space: ParameterSpace, provider: StiffnessProvider,
                      steps: dict[str, float] | None = None, *,
                      elements_through: float | None = SLOPE_ELEMENTS_THROUGH,
                      method: str | None = None) -> np.ndarray:
    """(n_chains, 5, 8): the change of each factor of ``compliance_factors`` per relative change
    of each chain dimension (``DIMENSION_SYMBOLS``: w, a, l, t1, t2) at the nominal chains of
    ``space`` [-].

    method (``SLOPE_METHODS``; None: ``SLOPE_METHOD``, "builds"): "condensed" (session 16):
    each nominal segment is solved once and its stiffness's derivative per dimension is the
    condensation's, U^T (dK/dp) U (``segment_stiffness_slopes``: assembly on meshes whose
    nodes the dimension moves, no factorisation), composed along the chain to the tangent
    of each factor; a mesher other than the mapped one, or ``elements_through`` set: "builds".
    "condensed-secant": the same segment derivatives composed at +-``steps`` (``SLOPE_STEPS``):
    the builds' secant with each segment's stiffness linear in the dimension.
    "builds" (the default): the central difference of full FEM builds at +-``steps``
    (``SLOPE_STEPS``), ``_slopes_by_builds`` (sessions 13-15): a secant, which follows the
    mapper's cell-count changes between the dimensions (docs/model.md 7, session 16); the only
    method for a tied provider (the condensed ones differentiate the rigidly joined segments)."""
    method = SLOPE_METHOD if method is None else method
    if method not in SLOPE_METHODS:
        raise ValueError(f"slope method {method!r} must be one of {', '.join(SLOPE_METHODS)}")
    if is_tied(provider) and method != "builds":
        raise ValueError(f"a tied provider's slopes are the builds of its own chains (method 'builds'), not "
                         f"{method!r}: the rigidly joined segments' (relative) slopes miss the tied chains' "
                         "(docs/model.md 7, 'Session 25')")
    if method != "builds" and elements_through is None and getattr(provider, "mesher", None) == "mapped":
        secant = SLOPE_STEPS if steps is None else steps
        return _slopes_condensed(space, provider, secant if method == "condensed-secant" else None)
    return _slopes_by_builds(space, provider, steps, elements_through=elements_through)


def _slopes_by_builds(space: ParameterSpace, provider: StiffnessProvider,
                      steps: dict[str, float] | None = None, *,
                      elements_through: float | None = SLOPE_ELEMENTS_THROUGH) -> np.ndarray:
    """(n_chains, 5, 8): the change of each factor of ``compliance_factors`` per relative change
    of each chain dimension (``DIMENSION_SYMBOLS``: w, a, l, t1, t2), by a central difference of
    +-``steps[symbol]`` (``SLOPE_STEPS`` by default) at the nominal chains of ``space`` [-]. Two
    provider solves per chain design and dimension (``same_design``: 20 chains for the reference
    mount's two designs), and a slice the moved dimension leaves as it was is the nominal chain's
    segment (``unchanged_slices``): 36 FEM segment builds where 90 were (L2 built apart from L1
    and all three slices of every moved chain), the same slopes to 1e-14.
    Central, not forward: the true dimensions sit up to 10 % either side of nominal, and a
    forward difference's slope is that of the secant to one side.
    A tied provider (``chain_stiffness``) on its own grid: each moved chain is condensed whole
    through its cut fields (``tied_chains.tied_chain_matrices``, 20 chains for the reference
    mount), since the rigidly joined segments' slopes miss how the cuts' axial compliance follows
    the dimensions (docs/model.md 7, "Session 25"); the nominal chains are built first (the
    factors then read them) and a moved chain reads each segment condensation the dimension leaves
    as it was (``unchanged_slices``' rule, through the segments' cache key): 42 segment
    condensations (6 of them the nominal chains') where 66 were (20 moved chains x 3, then the
    factors' 2 nominal chains x 3) for the reference mount's two designs, the same bits
    (docs/scale.md, "Issue 26, session 26").
    elements_through: the FEM grid of those builds (``slope_provider``; None, the default
    ``SLOPE_ELEMENTS_THROUGH``: ``provider``'s own); the segments' cache keys carry it. On
    another grid than ``provider``'s the slopes are that grid's relative change of each factor,
    d ln f / d ln P (the difference over the mean of the +- ratios), times the factor on
    ``provider``'s grid (``compliance_factors``): the grid's error of the factor itself (up to
    2.8 % at 3 through) cancels, and with it most of the slopes' (the torsion entry's 0.52 ->
    0.12 % of the factor at table1's dimensions; not enough for the form error, docs/model.md 7)."""
    fine, provider = provider, slope_provider(provider, elements_through)
    steps = difference_steps(provider) if steps is None else steps
    mech = space.mechanism
    design = same_design(mech.chains)
    moved = slope_moves(space, steps)
    # a slice a dimension leaves as it was (leaf 2's segment when t1 moves, leaf 1's when t2 moves,
    # the strut when w, a, t1 or t2 move) is the nominal chain's own segment: asked for as that,
    # it is built once
    shared = {(c, symbol, sign): unchanged_slices(mech.chains[c].chain, chain)
              for (c, symbol, sign), chain in moved.items()}

    def slices_of(key):
        nominal, chain = mech.chains[key[0]].chain, moved[key]
        return [(nominal if (x0, x1) in shared[key] else chain, x0, x1) for _, x0, x1 in chain_slices([chain])]

    # a tied provider (on its own grid or elements_through's): each moved chain condensed whole through its cut fields
    # (``tied_chains``), since the rigid cuts' slopes miss how the cuts' axial compliance follows
    # the dimensions (docs/model.md 7, "Session 25"); the nominal chains first, so that the moved
    # ones read the segment condensations a dimension leaves as they were from the cache
    tied = is_tied(provider)
    if tied:  # the chains keep their segment condensations, which the moved ones share
        nominals = [p.chain for c, p in enumerate(mech.chains) if design[c] == c]
        sharing = sharing_segments(provider)
        prepare_chains(sharing, list(dict.fromkeys([*nominals, *moved.values()])))  # parallel FEM builds
    else:
        prepare_provider(provider, list(dict.fromkeys(s for key in moved for s in slices_of(key))))
    done, out = {}, np.zeros((len(mech.chains), len(DIMENSION_SYMBOLS), 8))
    middle = np.zeros_like(out)  # the mean of the +- ratios: the factor on the slopes' grid, to O(step^2)
    for (c, symbol, sign), chain in moved.items():
        if chain not in done:
            nominal, same = mech.chains[c].chain, shared[c, symbol, sign]

            def asked(at, x0, x1, nominal=nominal, same=same):
                return provider(nominal if (x0, x1) in same else at, x0, x1)

            richer = provider_chain_compliance(chain, sharing if tied else asked)
            closed = chain_compliance_matrix(chain, mech.material)
            done[chain] = np.array([richer[i, j] / closed[i, j] for i, j in ENTRY_INDEX.values()])
        out[c, DIMENSION_SYMBOLS.index(symbol)] += sign * done[chain] / (2.0 * steps[symbol])
        middle[c, DIMENSION_SYMBOLS.index(symbol)] += 0.5 * done[chain]
    if provider is not fine:  # on a coarser grid: its relative slope times the factor on the provider's grid
        out *= compliance_factors(space, fine)[:, None, :] / np.where(middle == 0.0, 1.0, middle)  # 0: a design's copy
    return out[design]


# The slopes' methods (``compliance_slopes``): "condensed", the derivative of the nominal
# segments' condensation (one factorisation a segment, session 16), and "builds", the central
# difference of full FEM builds at +-SLOPE_STEPS (a factorisation a moved segment).
# The default stays "builds" (session 16, docs/model.md 7): the condensed tangent is the exact
# derivative of the nominal mesh's stiffness, but the mapper's cell counts change within the
# +-10 % the true dimensions span, and the builds' secant over +-3 % follows that better: on
# table1, cold `flexcal verify --model consistent` (idle, session 16's end) gives the same fit
# (max 0.0179 urad both; the 0.0094 once measured for the builds was another prior scale) but
# base-parameter z RMS 5.19 with the tangent against 1.29 with the builds, at 97.5 s against
# 147.8 s wall (docs/scale.md, session 16).
SLOPE_METHODS = ("condensed", "condensed-secant", "builds")
SLOPE_METHOD = "builds"
# The relative step of a dimension that morphs a segment's mesh for dK/dp: small enough that
# the mapped mesher keeps its connectivity on at least one side (table1's nominal leaves sit
# on a cell-count boundary for a, l and t1, where the other side's mesh has another topology:
# one-sided second order there), large enough that K(p + h) - K(p - h) keeps ~10 digits.
DERIVATIVE_STEP = 1e-4
# The step of the factors' central difference through the (cheap, closed-form) chain
# composition with the segments' stiffness linear in the dimension: a tangent, to O(1e-8).
TANGENT_STEP = 1e-4


def moved_chain(chain: FlexureChain, relative: dict[str, float]) -> FlexureChain:
    """``chain`` with each dimension symbol of ``relative`` scaled by (1 + its value)."""
    return dataclasses.replace(chain, **{DIMENSION_FIELDS[s]: getattr(chain, DIMENSION_FIELDS[s]) * (1.0 + r)
                                         for s, r in relative.items()})


def _moved(chain: FlexureChain, symbol: str, relative: float) -> FlexureChain:
    return moved_chain(chain, {symbol: relative})


def _slice_segment(chain: FlexureChain, index: int):
    """The meshed (canonical, first-half) segment of the slice ``index`` (0, 1, 2) of ``chain``."""
    from ..prototype.fem_provider import canonical_segment

    nodes = section_nodes(chain)
    segment, mirrored = canonical_segment(chain, float(nodes[index]), float(nodes[index + 1]))
    assert not mirrored
    return segment


def _slopes_parts(chain: FlexureChain, index: int, symbols, material, elements_through_thickness: float,
                  mesher: str, step: float) -> dict:
    from ..prototype.fem_provider import _segment_parts

    parts = _segment_parts(_slice_segment(chain, index), material, elements_through_thickness, mesher)
    return {**parts, "kind": "chain_segment_stiffness_slopes", "dimensions": list(symbols),
            "method": "condensed derivative U^T dK_r U, central or one-sided second order", "relative_step": step}


def segment_stiffness_slopes(chain: FlexureChain, index: int, symbols=None, *, material, elements_through_thickness,
                             mesher: str = "mapped", cache_directory=None, step: float = DERIVATIVE_STEP,
                             solver_threads: int = 0) -> dict[str, np.ndarray]:
    """{"stiffness": (12, 12), "slopes": (n_symbols, 12, 12)} [SI]: the FEM stiffness of the
    slice ``index`` (0, 1, 2: the meshed first half, ``section_nodes``) of ``chain`` and its
    derivative per relative change of each dimension ``symbols`` (``DIMENSION_SYMBOLS`` by
    default), cached (its own key, which names the method and ``step``). One mapped mesh and
    one factorisation (``fem.condense.solve_chain`` on the whole mesh of ``FAST_CHAIN_OPTIONS``;
    not the provider's numbers, whose cache entry it leaves alone); each dimension then costs two meshes and assemblies
    (``fem.condense.chain_stiffness_derivative``), or none when it leaves the slice as it was.
    solver_threads: unused (the executor's job option; an entry is computed on one thread,
    ``fem.cache.cached``)."""
    from flexcal.fem.cache import cached
    from flexcal.fem.condense import MorphedChain, chain_stiffness_derivative, solve_chain
    from flexcal.fem.mesh_mapped_chain import FAST_CHAIN_OPTIONS, mapped_mesh_chain
    from flexcal.geometry.exact import end_planes, pieces, reference_points
    from flexcal.model.parameters import DIMENSION_SYMBOLS

    if mesher != "mapped":
        raise ValueError("the condensed slopes need the mapped mesher (a mesh whose nodes a dimension moves)")
    symbols = tuple(DIMENSION_SYMBOLS if symbols is None else symbols)
    segment = _slice_segment(chain, index)

    def mesh_of(seg):
        return mapped_mesh_chain(seg, elements_through_thickness=elements_through_thickness, measure=False,
                                 quality=False, **FAST_CHAIN_OPTIONS)[0]

    def morphed(seg):
        planes, points = end_planes(seg), reference_points(seg)
        return MorphedChain(mesh=mesh_of(seg), plane_a=planes["A"], point_a=points["A"], plane_b=planes["B"],
                            point_b=points["B"])

    def compute() -> dict[str, np.ndarray]:
        mesh = mesh_of(segment)
        planes, points = end_planes(segment), reference_points(segment)
        solution = solve_chain(mesh, material, planes["A"], points["A"], planes["B"], points["B"])
        stiffness = 0.5 * (solution.stiffness + solution.stiffness.T)
        # not written under the provider's key (segment_cache_key): the provider's segments are on
        # PROTOTYPE_CHAIN_OPTIONS and condensed on their mirror part (session 16 / 17), other
        # numbers than this whole FAST_CHAIN_OPTIONS mesh's

        def same_mesh(other):
            return (other.mesh.nodes.shape == mesh.nodes.shape
                    and np.array_equal(np.asarray(other.mesh.tets), np.asarray(mesh.tets)))

        slopes = np.zeros((len(symbols), 12, 12))
        for k, symbol in enumerate(symbols):
            at = {sign: _slice_segment(_moved(chain, symbol, sign * step), index) for sign in (1, -1)}
            if all(pieces(at[sign]) == pieces(segment) and at[sign].x_start == segment.x_start
                   and at[sign].x_end == segment.x_end for sign in (1, -1)):
                continue  # the dimension leaves this slice as it was
            plus, minus = morphed(at[1]), morphed(at[-1])
            if same_mesh(plus) and same_mesh(minus):
                d = chain_stiffness_derivative(mesh, solution, material, plus, minus, 2.0 * step)
            else:  # the mesher's cell counts change on one side of nominal: second order on the other
                sign = 1 if same_mesh(plus) else -1
                far = morphed(_slice_segment(_moved(chain, symbol, 2 * sign * step), index))
                if not (same_mesh(plus if sign > 0 else minus) and same_mesh(far)):
                    raise ValueError(f"the mapped mesh of [{segment.x_start * 1e3:.1f}, {segment.x_end * 1e3:.1f}] "
                                     f"mm changes its cells within +-{2 * step:g} of {symbol}: no derivative")
                d = chain_stiffness_derivative(mesh, solution, material, plus if sign > 0 else minus, None,
                                               sign * step, plus_2=far)
            slopes[k] = 0.5 * (d + d.T)
        return {"stiffness": stiffness, "slopes": slopes}

    parts = _slopes_parts(chain, index, symbols, material, elements_through_thickness, mesher, step)
    return cached(parts, compute, cache_directory)


def _slopes_job(item, **options) -> dict[str, np.ndarray]:
    chain, index = item
    return segment_stiffness_slopes(chain, index, **options)


def _slopes_condensed(space: ParameterSpace, provider: StiffnessProvider,
                      secant: dict[str, float] | None = None) -> np.ndarray:
    """``compliance_slopes`` by the condensation's derivative: the tangent (method "condensed"),
    or with ``secant`` {symbol: relative step} the central difference over those steps with each
    segment's stiffness linear in the dimension (method "condensed-secant")."""
    import sys
    import time

    from flexcal.model.parameters import DIMENSION_SYMBOLS

    from ..executor import run_jobs, usable_cores, where
    from ..prototype.fem_provider import mirror_segment_stiffness, plan_local_builds

    mech = space.mechanism
    design = same_design(mech.chains)
    material = getattr(provider, "material", mech.material)
    options = {"symbols": tuple(DIMENSION_SYMBOLS), "material": material,
               "elements_through_thickness": float(provider.elements_through_thickness), "mesher": provider.mesher,
               "cache_directory": getattr(provider, "cache_directory", None)}
    items = [(mech.chains[c].chain, index) for c in range(len(mech.chains)) if design[c] == c for index in range(3)]
    results: dict = {}
    workers, scheduler = getattr(provider, "workers", 0), getattr(provider, "scheduler", None)
    if scheduler is None:
        import psutil

        n_workers, cores_each = plan_local_builds(workers, len(items), cores=usable_cores(),
                                                  available_bytes=psutil.virtual_memory().available)
    else:
        n_workers, cores_each = 0, 0
    progress = getattr(provider, "progress", False)
    start = time.perf_counter()
    if progress:
        print(f"  FEM slopes: {len(items)} segments (one factorisation each) on "
              f"{where(n_workers, scheduler, n_workers > 0)}", file=sys.stderr, flush=True)

    def on_done(item, result):
        results[item[0], item[1]] = result

    # the leaves first, the cheap strut last (as the builds)
    ordered = sorted(items, key=lambda item: item[1] == 2)
    failures = run_jobs(ordered, _slopes_job, on_done, key=lambda item: f"{hash(item[0]) & 0xffffffff:08x}-{item[1]}",
                        workers=n_workers, scheduler=scheduler, job_options={**options, "solver_threads": cores_each},
                        task_prefix="fem-slopes", in_threads=n_workers > 0)
    if failures:
        raise RuntimeError(f"{len(failures)} FEM slope job(s) failed, e.g. {next(iter(failures.values()))}")
    if progress:
        print(f"  FEM slopes: done in {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)

    out = np.zeros((len(mech.chains), len(DIMENSION_SYMBOLS), 8))
    for c in range(len(mech.chains)):
        if design[c] != c:
            continue
        nominal = mech.chains[c].chain
        base = [results[nominal, index] for index in range(3)]
        for k, symbol in enumerate(DIMENSION_SYMBOLS):
            factors = {}
            step = TANGENT_STEP if secant is None else secant[symbol]
            for sign in (1, -1):
                s = sign * step
                moved = _moved(nominal, symbol, s)
                # the five slices: 0, 1, 2 meshed, 3 and 4 the mirror images of 1 and 0
                linear = [base[i]["stiffness"] + s * base[i]["slopes"][k] for i in range(3)]
                segments = linear + [mirror_segment_stiffness(linear[1]), mirror_segment_stiffness(linear[0])]
                richer = _composed_compliance(moved, segments)
                closed = chain_compliance_matrix(moved, mech.material)
                factors[sign] = np.array([richer[i, j] / closed[i, j] for i, j in ENTRY_INDEX.values()])
            out[c, k] = (factors[1] - factors[-1]) / (2.0 * step)
    return out[design]


def corrected_space(space: ParameterSpace, provider: StiffnessProvider, *, slopes: bool = False) -> ParameterSpace:
    """``space`` whose model uses ``compliance_factors(space, provider)``; slopes: with their
    ``compliance_slopes`` too (the factors then follow the dimensions, docs/model.md 7)."""
    # the slopes first: the condensed slopes solve the nominal segments once and leave them in the
    # cache under the provider's own keys, so the factors that follow build only what they lack
    # (the builds ask for the nominal segments of the slices a dimension leaves as they were:
    # the same segments either way, the same numbers)
    extra = {"compliance_slopes": tuple(float(v) for v in compliance_slopes(space, provider).ravel())} if slopes else {}
    factors = compliance_factors(space, provider)
    return dataclasses.replace(space, compliance_factors=tuple(tuple(float(v) for v in row) for row in factors),
                               **extra)


# How a tied provider gives the model's dimension terms their moved chains (the slopes', the
# curvatures', the shortening slopes'): "derivatives", each from its nominal chain's segment
# condensations and their first and second derivatives in the five dimensions
# (``prototype.tied_taylor``: no FEM build per moved chain; session 40, docs/scale.md "Issue 26,
# session 40"), or "builds", a tied FEM chain built for each (sessions 25-39)
TERM_CHAINS = ("derivatives", "builds")
DEFAULT_TERM_CHAINS = "derivatives"


def model_provider(stiffness: str, mechanism, *, chains: str | None = None, **options) -> StiffnessProvider:
    """The stiffness provider of the model's FEM corrections for ``mechanism`` (None: the
    reference one): ``stiffness_provider(stiffness, **options)``, a tied one with the moves of each
    chain design (``same_design``) from its segments' derivatives when ``chains`` (None:
    ``DEFAULT_TERM_CHAINS``) is "derivatives" (``TERM_CHAINS``)."""
    from flexcal.model.parameters import parameter_space

    from ..prototype.providers import stiffness_provider

    chains = DEFAULT_TERM_CHAINS if chains is None else chains
    if chains not in TERM_CHAINS:
        raise ValueError(f"term chains {chains!r} must be one of {', '.join(TERM_CHAINS)}")
    provider = stiffness_provider(stiffness, **options)
    if chains == "builds" or not is_tied(provider):
        return provider
    from ..prototype.tied_taylor import taylor_tied_provider

    mechanism = parameter_space(mechanism).mechanism if mechanism is None else mechanism
    design = same_design(mechanism.chains)
    return taylor_tied_provider(provider, [p.chain for c, p in enumerate(mechanism.chains) if design[c] == c])


def model_space(stiffness: str = "fem", second_order: bool = True, *, progress: bool = False, workers: int | None = 0,
                scheduler: str | None = None, mechanism=None, breakaway_force: float | None = None,
                model: str = "second-order", also_build: Callable | None = None,
                after_batch: Callable[[], None] | None = None) -> ParameterSpace:
    """The parameter space of ``mechanism`` (the reference one by default) with the model
    options the calibration commands share.

    model (``MODELS``): "paper" is Eq. 1-8 as written (closed-form chains, no second-order
    terms; ``stiffness`` and ``second_order`` are not read); "second-order" takes ``stiffness``
    (``MODEL_STIFFNESS``) "fem" or "fem-rigid" (FEM-informed chain compliance from the provider of
    that name, FEM solves cached) or "closed-form" (the paper's Eq. 1) and ``second_order`` (the
    geometric second-order terms, ``flexcal.model.second_order``); "consistent" (``second_order``
    True only) with ``stiffness`` "fem" or "fem-rigid" is ``chain_kinematics.consistent_space``
    over that provider's factors with their slopes, with "closed-form" the same model on Eq. 1's
    chains with the chains' own shortening form (no measured correction); both with the
    clearance's play state at ``breakaway_force`` (None: ``DEFAULT_BREAKAWAY_N``). The quadratic
    dimension terms are added on top by ``dimension_terms.curved_space`` (which reads this
    module's slopes: the command line composes the two, ``cli.opening.calibration_model``).
    breakaway_force [N] for "second-order": the clearance's play state with that breakaway
    force (None: Eq. 7's memoryless clip; docs/model.md 9). workers / scheduler: where missing
    FEM segments are built (``fem_provider``). also_build(space, provider): for "consistent" on
    FEM chains, called with the provider before the slopes, to build what later terms will ask
    for in the same batch (``dimension_terms.prepare_model_chains``, which the command line passes
    for the quadratic dimension terms; a callable, since dimension_terms imports this module).
    after_batch(): called then, once that batch is built and before the model's set-up (its
    probes and joins: ``cli.opening.overlapped_opening`` starts the truth's FEM there)."""
    from flexcal.model.parameters import parameter_space

    if model not in MODELS:
        raise ValueError(f"model {model!r} must be one of {', '.join(MODELS)}")
    if stiffness not in MODEL_STIFFNESS:
        raise ValueError(f"model stiffness {stiffness!r} must be one of {', '.join(MODEL_STIFFNESS)}")
    space = parameter_space(mechanism)
    if model == "paper":
        return space
    if model == "consistent":
        if not second_order:
            raise ValueError("the consistent model is second-order by construction: drop --no-second-order, or use "
                             "--model second-order --no-second-order")
        force = DEFAULT_BREAKAWAY_N if breakaway_force is None else float(breakaway_force)
        if stiffness == "closed-form":  # Eq. 1's chains and the chains' own shortening form, nothing measured
            return dataclasses.replace(space, second_order=True, breakaway_force=force,
                                       chain_shortening=(0.0,) * (36 * len(space.mechanism.chains)))
        from .chain_kinematics import consistent_space

        provider = model_provider(stiffness, space.mechanism, progress=progress, workers=workers, scheduler=scheduler)
        if also_build is not None:  # e.g. the curvatures' chains in the same batch as the slopes'
            also_build(space, provider)
        if after_batch is not None:
            after_batch()
        space = consistent_space(corrected_space(space, provider, slopes=True), provider)
        return dataclasses.replace(space, breakaway_force=force)
    if stiffness != "closed-form":
        from ..prototype.providers import stiffness_provider

        space = corrected_space(space, stiffness_provider(stiffness, progress=progress, workers=workers,
                                                          scheduler=scheduler))
    return dataclasses.replace(space, second_order=bool(second_order), breakaway_force=breakaway_force)
