"""The nominal-measured corrections followed further into the candidate's dimensions (docs/model.md
11, session 18): the FEM compliance factors to second order, the chains' shortening correction to
first order.

``model_correction.compliance_slopes`` makes each chain-compliance factor follow the candidate's
dimensions linearly, ``f(P) = f(P0) + sum_k g_k r_k`` with r = P / P0 - 1 (docs/model.md 7). At
the true dimensions (up to +-10 % off nominal) the FEM factors leave that line by up to 0.3 % on
the bending entries and 2 % on torsion, smoothly and quadratically along the path from nominal
to the as-built chain (measured, session 18). A nut in its gap amplifies a bending error of a
driving chain through its load by mu / (1 - mu) (up to 13x): on the designed trajectories (2-2.5
mm strokes, most postures with a nut in its gap) that was most of the consistent model's form
error. The curvatures H (n_chains, 5, 5, 8) give the factors' second-order term ``1/2 r^T H r``:

- diagonal: ``(f(+s_k) + f(-s_k) - 2 f0) / s_k^2`` from the slopes' own builds at +-``SLOPE_STEPS``
  (no new FEM build: their segments are in the cache) and the nominal factors;
- mixed, by default (``DEFAULT_PAIR_DIFFERENCES``, session 30): ``(f(+s_k, +s_m) - f(+s_k) -
  f(+s_m) + f0) / (s_k s_m)``, one moved chain per pair of dimensions (10 per chain design,
  ``same_design`` as the slopes), accurate to O(s); ``pairs="central"``: ``(f(+s_k, +s_m) +
  f(-s_k, -s_m) - 2 f0 - s_k^2 H_kk - s_m^2 H_mm) / (2 s_k s_m)``, two per pair, O(s^2) like the
  slopes (the default of sessions 18-29). Only the slices both dimensions of the pair reach are
  built (``slice_owners``): t1 reaches leaf 1's slice only, t2 leaf 2's, w and a both leaves', l
  all three (it moves the section nodes), and a slice one of them leaves as it was is the other
  one's single-move segment (or the nominal one), the same solid and so the same numbers: 24
  segment builds for the reference mount one-sided, 48 central, where 96 were (session 20,
  docs/model.md 11).

The shortening correction ``S_measured(P0) - S_elements(P0)`` (``chain_kinematics``, docs/model.md
10) is 0.3-0.4 % of the driving chains' S_zz off at the true dimensions; with the factors right
that error is what the walks show (session 18). Its slopes (n_chains, 5, 6, 6) are the central
difference of the same probe on the slopes' moved chains (their segments cached: no FEM build).

Measured once at the nominal chains, like the factors and slopes; ``model/`` only receives the
numbers (``ParameterSpace.compliance_curvatures``, ``ParameterSpace.shortening_slopes``). A tied
provider (``chain_stiffness``, ``--model-stiffness fem``) is asked for each moved chain whole
(its segments joined through the cut fields; the segments it shares with the nominal chain and
the single moves read from the cache): 40 tied chains for the reference mount's curvatures (60
central), 20 of them the slopes' (the shortening slopes ask for those 20 only). The model's
provider by default (``model_correction.model_provider``, session 40) gives those moved chains
from the nominal segments' first and second derivatives (``prototype.tied_taylor``), no build
each, and its ``difference_steps`` (0.3 %) replace ``SLOPE_STEPS`` in every difference here.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from flexcal.geometry.params import FlexureChain
from flexcal.model.chain import chain_compliance_matrix
from flexcal.model.hinge import ENTRY_INDEX
from flexcal.model.parameters import DIMENSION_SYMBOLS, ParameterSpace

from ..prototype.segments import (StiffnessProvider, chain_slices, is_tied, prepare_chains, prepare_provider,
                                  sharing_segments)
from .chain_kinematics import chain_shortening
from .model_correction import (SLOPE_ELEMENTS_THROUGH, SLOPE_STEPS, compliance_factors, difference_steps, moved_chain,
                               provider_chain_compliance, same_design, slope_moves, slope_provider, unchanged_slices)

__all__ = ["PAIR_DIFFERENCES", "DEFAULT_PAIR_DIFFERENCES", "CURVATURE_TERMS", "MIXED_ELEMENTS_THROUGH",
           "compliance_curvatures", "shortening_slopes", "curved_space", "curvature_moves", "prepare_model_chains",
           "moved_chain", "moved_factors", "slice_owners"]


def slice_owners(chain: FlexureChain, alike) -> dict[tuple[float, float], FlexureChain]:
    """{slice (x_start, x_end) [m]: the first chain of ``alike`` whose same slice is the same solid}
    for the slices of ``chain`` one of them shares (``unchanged_slices``: same section nodes, same
    pieces), so a provider asked for it as that chain's builds it once, with the same numbers."""
    owners: dict[tuple[float, float], FlexureChain] = {}
    for other in alike:
        for piece in unchanged_slices(other, chain):
            owners.setdefault(piece, other)
    return owners


def _shared(alike, chain: FlexureChain, provider: StiffnessProvider) -> StiffnessProvider:
    """``provider`` asking for a slice ``chain`` shares with a chain of ``alike`` (a sequence of
    chains; ``slice_owners``) as that chain's (the same segment, built once); a tied provider
    itself (its chains are condensed whole: no segment to share, docs/model.md 7 "Session 25")."""
    if is_tied(provider):
        return provider
    owners = slice_owners(chain, alike)

    def asked(at, x0, x1):
        return provider(owners.get((x0, x1), at), x0, x1)

    return asked


def moved_factors(nominal: FlexureChain, chain: FlexureChain, provider: StiffnessProvider, material,
                  alike=()) -> np.ndarray:
    """(8,) provider / closed form of ``chain`` (a slice it shares with ``nominal`` or a chain of
    ``alike`` that chain's: ``slice_owners``)."""
    richer = provider_chain_compliance(chain, _shared([nominal, *alike], chain, provider))
    closed = chain_compliance_matrix(chain, material)
    return np.array([richer[i, j] / closed[i, j] for i, j in ENTRY_INDEX.values()])


PAIR_DIFFERENCES = ("central", "one-sided")
# The mixed entries by default from the (+s_k, +s_m) moves alone (session 30): 20 tied chains of
# the reference mount where the central differences build 40 (the curvatures' cold wall 92 -> 43
# s, idle). Their O(s) term moves the form error at the true values by -0.02 to +0.02 urad RMS per
# angle against the central ones, <= 0.11 everywhere measured (table1 and paper, scenario seeds
# 1-3, standard, design and six walks, breakaway 0.5 / 2 / 5 N; docs/model.md 11, "Session 30")
DEFAULT_PAIR_DIFFERENCES = "one-sided"


CURVATURE_TERMS = ("all", "diagonal", "mixed")
# The grid of the mixed curvatures' builds by default: None, the diagonal's (the slopes' grid).
# A number n: the mixed entries are that grid's relative ones (``on_grid(n)``, nominal, single and
# pair moves on it) times the factor on the provider's grid, the diagonal stays on the slopes'
# builds (docs/model.md 11, "Session 37"; session 19 measured it on the rigid cuts)
MIXED_ELEMENTS_THROUGH: float | None = None


def curvature_moves(space: ParameterSpace, steps: dict[str, float] | None = None, *,
                    pairs: str = DEFAULT_PAIR_DIFFERENCES, terms: str = "all") -> dict[tuple, FlexureChain]:
    """{(chain index, k, m, sign): the moved chain} of ``compliance_curvatures``' builds: each
    chain design's first chain (``same_design``) with dimension k moved by sign step (k == m,
    the slopes' own chains) or k and m both (``pairs``: sign +1 and -1 "central", +1 alone
    "one-sided"), in the order the builds ask for them. terms (``CURVATURE_TERMS``): "all";
    "diagonal", the single moves alone; "mixed", the pairs and the single moves their formula
    reads (+1 alone for one-sided pairs)."""
    if pairs not in PAIR_DIFFERENCES:
        raise ValueError(f"pairs={pairs!r} must be one of {', '.join(PAIR_DIFFERENCES)}")
    if terms not in CURVATURE_TERMS:
        raise ValueError(f"terms={terms!r} must be one of {', '.join(CURVATURE_TERMS)}")
    steps = SLOPE_STEPS if steps is None else steps
    mech = space.mechanism
    design = same_design(mech.chains)
    single_signs = (1,) if terms == "mixed" and pairs == "one-sided" else (1, -1)
    moves = {}
    for c in (c for c in range(len(mech.chains)) if design[c] == c):
        for k, symbol in enumerate(DIMENSION_SYMBOLS):
            for sign in single_signs:
                moves[c, k, k, sign] = {symbol: sign * steps[symbol]}
        if terms == "diagonal":
            continue
        for k, m in itertools.combinations(range(len(DIMENSION_SYMBOLS)), 2):
            for sign in ((1, -1) if pairs == "central" else (1,)):
                moves[c, k, m, sign] = {DIMENSION_SYMBOLS[k]: sign * steps[DIMENSION_SYMBOLS[k]],
                                        DIMENSION_SYMBOLS[m]: sign * steps[DIMENSION_SYMBOLS[m]]}
    return {key: moved_chain(mech.chains[key[0]].chain, relative) for key, relative in moves.items()}


def prepare_model_chains(space: ParameterSpace, provider: StiffnessProvider, *,
                         pairs: str = DEFAULT_PAIR_DIFFERENCES,
                         mixed_elements_through: float | None = MIXED_ELEMENTS_THROUGH) -> None:
    """Build at once, in one batch on the executor, every chain the consistent model's FEM
    corrections with quadratic dimension terms will ask a tied ``provider`` for: the mount's
    nominal chains (every placement's: L2, 1 ulp longer than L1, has its own shortening probe,
    ``chain_kinematics.shortening_corrections``), the slopes' moved chains (``slope_moves``)
    and the curvatures' (``curvature_moves``), each keeping its segment condensations for the
    moved chains that share them (``sharing_segments``). The phases then read them from the
    cache: asked for phase by phase, L2's probe chain was built alone on one of the two cores
    (6 s) and each batch's end left a core idle (docs/scale.md, "Issue 26, session 31"). With
    the mixed curvatures on another grid (``mixed_elements_through``), their chains on it (the
    nominal ones, single and pair moves) in a second batch after. Any other provider: nothing
    (its segments are prepared phase by phase)."""
    if not is_tied(provider):
        return
    coarse = None if mixed_elements_through is None else slope_provider(provider, mixed_elements_through)
    coarse = None if coarse is provider else coarse
    chains = [p.chain for p in space.mechanism.chains]
    steps = difference_steps(provider)
    chains += [*slope_moves(space, steps).values(),
               *curvature_moves(space, steps, pairs=pairs, terms="all" if coarse is None else "diagonal").values()]
    prepare_chains(sharing_segments(provider), list(dict.fromkeys(chains)))
    if coarse is not None:  # the small jobs last: less of a core idle at the batch's end
        designs = same_design(space.mechanism.chains)
        mixed = [*(p.chain for c, p in enumerate(space.mechanism.chains) if designs[c] == c),
                 *curvature_moves(space, difference_steps(coarse), pairs=pairs, terms="mixed").values()]
        prepare_chains(sharing_segments(coarse), list(dict.fromkeys(mixed)))


def compliance_curvatures(space: ParameterSpace, provider: StiffnessProvider,
                          steps: dict[str, float] | None = None, *,
                          pairs: str = DEFAULT_PAIR_DIFFERENCES,
                          elements_through: float | None = SLOPE_ELEMENTS_THROUGH,
                          mixed_elements_through: float | None = MIXED_ELEMENTS_THROUGH) -> np.ndarray:
    """(n_chains, 5, 5, 8): the second derivative of each factor of ``compliance_factors`` per
    relative change of two chain dimensions (``DIMENSION_SYMBOLS``: w, a, l, t1, t2) at the
    nominal chains of ``space`` [-] (module docstring), symmetric in the two dimensions.

    pairs (``PAIR_DIFFERENCES``): the mixed entries from both pair moves, (+s_k, +s_m) and
    (-s_k, -s_m) ("central", O(s^2)), or from (+s_k, +s_m) alone ("one-sided":
    ``(f(+s_k, +s_m) - f(+s_k) - f(+s_m) + f0) / (s_k s_m)``, O(s), half the pair builds).
    elements_through: the grid of the builds (``slope_provider``; None, the default: ``provider``'s
    own), as for the slopes: on another grid, that grid's relative curvature (H over its own
    nominal factor) times the factor on ``provider``'s grid (measured and rejected as the
    default, docs/model.md 11 "Session 36").
    mixed_elements_through: the mixed entries' grid alone (None, the default
    ``MIXED_ELEMENTS_THROUGH``: the diagonal's), the same relative rule; the diagonal stays on
    ``elements_through`` (the slopes' own builds)."""
    if mixed_elements_through is None:
        return _curvatures(space, provider, steps, pairs, elements_through, "all")
    return (_curvatures(space, provider, steps, pairs, elements_through, "diagonal")
            + _curvatures(space, provider, steps, pairs, mixed_elements_through, "mixed"))


def _curvatures(space: ParameterSpace, provider: StiffnessProvider, steps, pairs: str,
                elements_through: float | None, terms: str) -> np.ndarray:
    """``compliance_curvatures``' ``terms`` (``CURVATURE_TERMS``; the others zero) on the grid
    ``elements_through``: its builds (``curvature_moves``) and finite differences."""
    fine, provider = provider, slope_provider(provider, elements_through)
    other_grid = provider is not fine
    steps = difference_steps(provider) if steps is None else steps
    mech = space.mechanism
    design = same_design(mech.chains)
    first = [c for c in range(len(mech.chains)) if design[c] == c]
    chains = curvature_moves(space, steps, pairs=pairs, terms=terms)
    # a slice of a pair's chain that only one of its two dimensions (or neither) reaches is that
    # single move's (or the nominal chain's) segment: t1 reaches leaf 1's slice only, t2 leaf 2's,
    # w and a both leaves', l all three (it moves the nodes); 48 segment builds where 96 were
    alike = {key: [mech.chains[key[0]].chain] + ([chains[key[0], key[1], key[1], key[3]],
                                                 chains[key[0], key[2], key[2], key[3]]] if key[1] != key[2] else [])
             for key in chains}
    if is_tied(provider):  # parallel FEM builds: the moved chains whole, sharing their segments
        provider = sharing_segments(provider)
        prepare_chains(provider, list(dict.fromkeys(chains.values())))
    else:  # parallel FEM builds: the moved chains' own slices, each shared one once
        slices = []
        for key, chain in chains.items():
            owners = slice_owners(chain, alike[key])
            slices += [(owners.get((x0, x1), chain), x0, x1) for _, x0, x1 in chain_slices([chain])]
        prepare_provider(provider, list(dict.fromkeys(slices)))
    ratio = {key: moved_factors(alike[key][0], chain, provider, mech.material, alike[key][1:])
             for key, chain in chains.items()}
    nominal = compliance_factors(space, provider)
    h = np.array([steps[s] for s in DIMENSION_SYMBOLS])
    out = np.zeros((len(mech.chains), len(DIMENSION_SYMBOLS), len(DIMENSION_SYMBOLS), 8))
    diagonal = np.zeros_like(out)
    for c in first:
        if (c, 0, 0, -1) in chains:  # both single moves built: the diagonal
            for k in range(len(DIMENSION_SYMBOLS)):
                diagonal[c, k, k] = (ratio[c, k, k, 1] + ratio[c, k, k, -1] - 2.0 * nominal[c]) / h[k] ** 2
        if terms == "diagonal":
            continue
        for k, m in itertools.combinations(range(len(DIMENSION_SYMBOLS)), 2):
            if pairs == "central":
                both = ratio[c, k, m, 1] + ratio[c, k, m, -1] - 2.0 * nominal[c]
                mixed = (both - h[k] ** 2 * diagonal[c, k, k] - h[m] ** 2 * diagonal[c, m, m]) / (2.0 * h[k] * h[m])
            else:
                mixed = (ratio[c, k, m, 1] - ratio[c, k, k, 1] - ratio[c, m, m, 1] + nominal[c]) / (h[k] * h[m])
            out[c, k, m] = out[c, m, k] = mixed
    if terms != "mixed":
        out += diagonal
    if other_grid:  # on another grid: its relative curvature times the factor on the provider's grid
        out *= (compliance_factors(space, fine) / np.where(nominal == 0.0, 1.0, nominal))[:, None, None, :]
    return out[design]


def shortening_slopes(space: ParameterSpace, provider: StiffnessProvider,
                      steps: dict[str, float] | None = None, *,
                      elements_through: float | None = SLOPE_ELEMENTS_THROUGH) -> np.ndarray:
    """(n_chains, 5, 6, 6): the change of each chain's shortening correction
    (``chain_kinematics.shortening_corrections``) per relative change of each dimension at the
    nominal chains of ``space`` [1/m, 1, m]: central differences at +-``SLOPE_STEPS``, probed on
    the slopes' moved chains on their grid (``elements_through``, ``slope_provider``)."""
    from flexcal.model.shortening import chain_shortening_form

    provider = slope_provider(provider, elements_through)
    steps = difference_steps(provider) if steps is None else steps
    mech = space.mechanism
    design = same_design(mech.chains)
    out = np.zeros((len(mech.chains), len(DIMENSION_SYMBOLS), 6, 6))
    for c in (c for c in range(len(mech.chains)) if design[c] == c):
        nominal = mech.chains[c].chain
        for k, symbol in enumerate(DIMENSION_SYMBOLS):
            for sign in (1, -1):
                chain = moved_chain(nominal, {symbol: sign * steps[symbol]})
                measured, _ = chain_shortening(chain, _shared([nominal], chain, provider))
                own = chain_shortening_form(chain.length, chain.hinge_length, chain.width, chain.fillet,
                                            chain.thickness_1, chain.thickness_2, section=chain.section,
                                            connector_length=chain.connector_length,
                                            end_block_length=chain.end_block_length, material=mech.material)
                out[c, k] += sign * (measured - own) / (2.0 * steps[symbol])
    return out[design]


def curved_space(space: ParameterSpace, provider: StiffnessProvider, *,
                 pairs: str = DEFAULT_PAIR_DIFFERENCES,
                 elements_through: float | None = SLOPE_ELEMENTS_THROUGH,
                 mixed_elements_through: float | None = MIXED_ELEMENTS_THROUGH) -> ParameterSpace:
    """``space`` (a consistent space with ``compliance_slopes``) whose factors follow the
    dimensions to second order and whose shortening correction follows them:
    ``compliance_curvatures`` (``pairs``) and ``shortening_slopes`` of ``space`` and ``provider``,
    built on ``elements_through`` (the slopes' grid; None: the provider's own), the mixed
    curvatures on ``mixed_elements_through`` (``compliance_curvatures``)."""
    if not (space.compliance_slopes and space.chain_shortening):
        raise ValueError("curved_space needs a consistent space with compliance slopes "
                         "(chain_kinematics.consistent_space over corrected_space(..., slopes=True))")
    return dataclasses.replace(
        space, compliance_curvatures=tuple(float(v) for v in compliance_curvatures(
            space, provider, pairs=pairs, elements_through=elements_through,
            mixed_elements_through=mixed_elements_through).ravel()),
        shortening_slopes=tuple(float(v) for v in shortening_slopes(space, provider,
                                                                    elements_through=elements_through).ravel()))
