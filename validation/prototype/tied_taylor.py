"""The model's moved tied chains from shape derivatives of their nominal chain's segment
condensations, instead of a FEM build per moved chain (issue 26's route; docs/scale.md, "Issue
26, session 40").

The model's dimension terms (``runs.model_correction`` slopes, ``runs.dimension_terms``
curvatures and shortening slopes) ask a tied provider for ~20 chains per chain design, each the
nominal chain with one or two of its five dimensions (``DIMENSION_SYMBOLS``) moved by a few per
cent: 40 tied chain builds for the reference mount, most of the cold main job. Here each of the
nominal chain's three distinct segment condensations (``cut_fields.interface_condensations``)
is computed once with its first and second derivatives in the five relative dimensions
(``fem.condense_taylor``: the segment meshed on the nominal segment's cells,
``fem.mesh_mapped_chain.template_grid``, one factorisation per parity class), cached, and a
moved chain's segments are that second-order polynomial at its relative dimensions r, joined as
``tied_chains.tied_chain_matrices`` joins built ones. At r = 0 the polynomial is the nominal
condensation to the bit, so the differences the terms take (+-3 %, pairs one-sided) are those of
the derivatives: session 37 measured terms on the nominal cells at 1 % and 3 % steps the same to
0.01 urad of form error (docs/model.md 11), which is what these are.

``taylor_tied_provider(provider, nominal_chains)`` wraps a tied provider (``tied_chains.
tied_fem_provider``): ``nominal_chains``, their rounding twins (``ROUNDING_TWIN``: a chain of the
same design whose length the mount's geometry rounded otherwise) and their moves come from the
polynomials (a nominal chain's at r = 0 is its build to the bit; a twin's is its nominal chain's
segments joined on its own plan), any other chain is the provider's own build."""

from __future__ import annotations

import dataclasses
import sys
import time
from typing import Any, Iterable

import numpy as np

from flexcal.geometry.params import STEEL, FlexureChain, Material

__all__ = ["TAYLOR_REACH", "DIFFERENCE_STEP", "ROUNDING_TWIN", "relative_dimensions", "segment_taylor_key",
           "segment_taylors", "taylor_chain_matrices", "build_segment_taylors", "taylor_tied_provider"]

# the largest relative move of a dimension served from the polynomials: the dimension terms' steps
# (3 %, 2.5 %) and their pairs; a chain moved further is built (the polynomial's error grows as r^3)
TAYLOR_REACH = 0.05

# the relative step of the dimension terms' differences on these chains (``runs.model_correction.
# difference_steps``): the segments' polynomials are derivatives, exact to second order; their third
# order is not the chains' (a segment's stiffness goes as 1 / length^3, the chain's compliance nearly
# linearly), so at the builds' 3 % the l slopes of table1's chains came out 0.015-0.02 (10-20 %) off
# the builds' and the template cells' differences, at 0.3 % within 4e-4 of them (session 40)
DIFFERENCE_STEP = 3e-3

# the modules of flexcal.validation whose code computes a segment's Taylor entry (its cache key's
# "code"; every key carries flexcal.fem's and flexcal.geometry's already, ``fem.cache.code_version``)
TAYLOR_CODE = ("flexcal.validation.prototype.tied_taylor", "flexcal.validation.prototype.tied_chains",
               "flexcal.validation.prototype.cut_fields", "flexcal.validation.prototype.segments")


def _symbols() -> list[str]:
    from flexcal.model.parameters import DIMENSION_SYMBOLS

    return list(DIMENSION_SYMBOLS)


def _fields() -> list[str]:
    from flexcal.model.parameters import DIMENSION_FIELDS, DIMENSION_SYMBOLS

    return [DIMENSION_FIELDS[s] for s in DIMENSION_SYMBOLS]


# how far (relative) a chain's other fields may sit from its nominal chain's and still be that chain:
# the mount computes each chain's length from its anchor points, so chains of one design differ by
# rounding (table1's L2 is 1 ulp longer than L1 and L3); 8 ulps, far below any real change
ROUNDING_TWIN = 8 * np.finfo(float).eps


def _same_but_rounding(chain: FlexureChain, nominal: FlexureChain) -> bool:
    """Whether ``chain`` is ``nominal`` but for the rounding of its float fields (``ROUNDING_TWIN``)."""
    for field in dataclasses.fields(nominal):
        mine, theirs = getattr(chain, field.name), getattr(nominal, field.name)
        if mine != theirs and not (isinstance(theirs, float) and isinstance(mine, float)
                                   and abs(mine - theirs) <= ROUNDING_TWIN * abs(theirs)):
            return False
    return True


def relative_dimensions(chain: FlexureChain, nominals: Iterable[FlexureChain],
                        reach: float = TAYLOR_REACH) -> tuple[FlexureChain, np.ndarray] | None:
    """(nominal chain, r (5,)): ``chain`` is that chain of ``nominals`` with its five dimensions
    (``DIMENSION_SYMBOLS``) scaled by (1 + r), |r| <= reach, everything else equal but for
    rounding (``ROUNDING_TWIN``: the nominal chain itself and its rounding twins have r = 0); None
    if it is no such chain."""
    fields = _fields()
    for nominal in nominals:
        if not _same_but_rounding(dataclasses.replace(chain, **{f: getattr(nominal, f) for f in fields}), nominal):
            continue
        r = np.array([getattr(chain, f) / getattr(nominal, f) - 1.0 for f in fields])
        if np.all(np.abs(r) <= reach):
            return nominal, r
    return None


def _moved(nominal: FlexureChain, r: np.ndarray) -> FlexureChain:
    return dataclasses.replace(nominal, **{f: getattr(nominal, f) * (1.0 + float(x)) for f, x in zip(_fields(), r)})


def _distinct_steps(nominal: FlexureChain, ties: str) -> dict[tuple, int]:
    """{plan_key of the nominal chain: the index of its first step in the plan}: its distinct
    condensations (``cut_fields.interface_condensations``)."""
    from .cut_fields import plan_key, step_interfaces
    from .tied_chains import _tied_plan

    plan, interfaces, _, _ = _tied_plan(nominal, ties)
    out: dict[tuple, int] = {}
    for index, (step, labels) in enumerate(zip(plan, step_interfaces(plan, interfaces))):
        out.setdefault(plan_key(step, labels), index)
    return out


def _same_solid(segment, other) -> bool:
    """Whether two segments are the same solid: the same ends and pieces (``geometry.exact.pieces``,
    all a segment's mesh and end faces are made of; ``runs.model_correction.unchanged_slices``)."""
    from flexcal.geometry.exact import pieces

    return (segment.x_start, segment.x_end) == (other.x_start, other.x_end) and pieces(segment) == pieces(other)


def _segment_taylor_parts(nominal: FlexureChain, index: int, ties: str, material: Material,
                          elements_through_thickness: float, step: float) -> dict:
    from flexcal.fem.cache import sources_digest
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS

    from .tied_chains import TIED_STRUT_REFINEMENT, cut_interfaces

    if material != STEEL:
        raise ValueError("tied chains are condensed in STEEL only (cut_fields' condensations)")
    return {"kind": "tied_segment_taylor", "code": sources_digest(*TAYLOR_CODE), "chain": nominal,
            "step_index": int(index), "material": material, "ties": list(cut_interfaces(ties)),
            "derivative_step": float(step),
            "mesh": {"mesher": "mapped", "elements_through_thickness": float(elements_through_thickness),
                     "options": PROTOTYPE_CHAIN_OPTIONS, "strut_refinement": TIED_STRUT_REFINEMENT,
                     "mirrored": True, "template": "nominal"}}


def segment_taylor_key(nominal: FlexureChain, index: int, ties: str, material: Material = STEEL, *,
                       elements_through_thickness: float, step: float | None = None) -> str:
    """The FEM cache key of ``segment_taylors``' entry for step ``index`` of ``nominal``'s plan."""
    from flexcal.fem.cache import cache_key
    from flexcal.fem.condense_taylor import DERIVATIVE_STEP

    return cache_key(_segment_taylor_parts(nominal, index, ties, material, elements_through_thickness,
                                           DERIVATIVE_STEP if step is None else step))


def _compute_segment_taylor(nominal: FlexureChain, index: int, ties: str, elements_through_thickness: float,
                            step: float) -> dict[str, np.ndarray]:
    """{"value", "parameters", "first", "second"}: the condensation of step ``index`` of
    ``nominal``'s plan (as ``cut_fields.interface_segment_stiffness``, before its symmetrising)
    and its derivatives in the reached relative dimensions (``parameters``, indices into
    ``DIMENSION_SYMBOLS``), the segment meshed on the nominal segment's cells."""
    from flexcal.fem.condense_taylor import mirrored_coupled_stiffness_taylor
    from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain_mirror_part

    from .cut_fields import segment_couplings, step_interfaces
    from .tied_chains import _tied_plan

    plan0, interfaces, options, scale0 = _tied_plan(nominal, ties)
    labels = step_interfaces(plan0, interfaces)[index]
    template, _, starts0, ends0 = plan0[index]
    mesh0, axes = mapped_mesh_chain_mirror_part(template, elements_through_thickness=elements_through_thickness,
                                                template=template, **options)
    couplings0 = segment_couplings(template, mesh0, starts0, ends0, labels, scale0)

    def part_at(r):
        plan, _, _, scale = _tied_plan(_moved(nominal, r), ties)
        segment, _, starts, ends = plan[index]
        if _same_solid(segment, template) and scale == scale0:
            return mesh0, couplings0  # a dimension this segment does not have (as ``unchanged_slices``)
        mesh, moved_axes = mapped_mesh_chain_mirror_part(segment, elements_through_thickness=elements_through_thickness,
                                                         template=template, **options)
        if moved_axes != axes:
            raise ValueError("a moved segment's mirror axes differ from the nominal one's")
        return mesh, segment_couplings(segment, mesh, starts, ends, labels, scale)

    n = len(_fields())
    taylor = mirrored_coupled_stiffness_taylor(part_at, STEEL, axes, n, step=step)
    reached = np.array([p for p in range(n) if np.any(taylor.first[p]) or np.any(taylor.second[p])], int)
    return {"value": taylor.value, "parameters": reached, "first": taylor.first[reached],
            "second": taylor.second[np.ix_(reached, reached)]}


def segment_taylors(nominal: FlexureChain, ties: str, material: Material = STEEL, *, elements_through_thickness: float,
                    cache_directory=None, step: float | None = None) -> dict[tuple, dict[str, np.ndarray]]:
    """{plan_key: ``_compute_segment_taylor``'s arrays} of ``nominal``'s distinct segment
    condensations, each read from or stored in the FEM cache (``flexcal.fem.cache.cached``)."""
    from flexcal.fem.cache import cached
    from flexcal.fem.condense_taylor import DERIVATIVE_STEP

    step = DERIVATIVE_STEP if step is None else step
    out = {}
    for key, index in _distinct_steps(nominal, ties).items():
        parts = _segment_taylor_parts(nominal, index, ties, material, elements_through_thickness, step)
        out[key] = cached(parts, lambda index=index: _compute_segment_taylor(nominal, index, ties,
                                                                             elements_through_thickness, step),
                          cache_directory)
    return out


def _at(entry: dict[str, np.ndarray], r: np.ndarray) -> np.ndarray:
    """The symmetric condensation of a ``segment_taylors`` entry at relative dimensions r (5,)."""
    reached = np.asarray(entry["parameters"], int)
    x = np.asarray(r, float)[reached]
    k = (entry["value"] + np.einsum("p,pij->ij", x, entry["first"])
         + 0.5 * np.einsum("p,q,pqij->ij", x, x, entry["second"]))
    return 0.5 * (k + k.T)


def taylor_chain_matrices(chain: FlexureChain, nominal: FlexureChain, taylors: dict, ties: str) -> dict[str, np.ndarray]:
    """{"stiffness": K_chain (30, 30), "segments": (5, 12, 12)} [SI] of ``chain``, a move of
    ``nominal`` (``relative_dimensions``), as ``tied_chains.tied_chain_matrices`` gives them, its
    segment condensations from ``taylors`` (``segment_taylors`` of ``nominal``) at its r, on one
    thread."""
    from flexcal.fem.solve import one_thread

    with one_thread():  # the dense algebra's bits as a built chain's (``fem.cache.cached`` computes on one thread)
        return _taylor_chain_matrices(chain, nominal, taylors, ties)


def _taylor_chain_matrices(chain: FlexureChain, nominal: FlexureChain, taylors: dict, ties: str) -> dict:
    from flexcal.fem.cut_warping import chain_twist_stiffness, rigid_part_stiffness

    from .cut_fields import chain_order_matrices, cut_orders, plan_key, step_interfaces
    from .tied_chains import _tied_plan

    found = relative_dimensions(chain, [nominal], reach=np.inf)
    if found is None:
        raise ValueError("the chain is no move of the nominal chain given (tied_taylor.relative_dimensions)")
    r = found[1]
    plan, interfaces, _, scale = _tied_plan(chain, ties)
    plan0, _, _, _ = _tied_plan(nominal, ties)
    labels0 = step_interfaces(plan0, interfaces)
    condensed = {}
    for index, (step, labels) in enumerate(zip(plan, step_interfaces(plan, interfaces))):
        key = plan_key(step, labels)
        if key in condensed:
            continue
        own = plan_key(plan0[index], labels0[index])  # the nominal step this one moves
        if own not in taylors:
            raise ValueError("the moved chain's plan does not follow its nominal chain's")
        condensed[key] = _at(taylors[own], r)
    matrices, orders = chain_order_matrices(plan, condensed, interfaces), cut_orders(plan, interfaces)
    return {"stiffness": chain_twist_stiffness(matrices, orders, scale),
            "segments": rigid_part_stiffness(matrices, orders, scale)}


def build_segment_taylor_job(item: tuple, *, ties: str, material: Material, elements_through_thickness: float,
                             step: float, cache_directory=None, mesher_threads: int = 0,
                             solver_threads: int = 0) -> dict[str, Any]:
    """One job of ``build_segment_taylors``' batch on a job thread: item ("taylor", nominal chain,
    step index), that segment's Taylor entry (``segment_taylors``), or ("chain", chain), its tied
    chain (``tied_chains.build_tied_chain_job``); {"key", its arrays, "wall_s"}; PARDISO on
    ``solver_threads`` MKL threads (0: all)."""
    import contextlib

    from flexcal.fem.cache import cached
    from flexcal.fem.solve import solver_threads as mkl_threads

    from .tied_chains import build_tied_chain_job

    if item[0] == "chain":
        return build_tied_chain_job(item[1], ties=ties, material=material,
                                    elements_through_thickness=elements_through_thickness,
                                    cache_directory=cache_directory, solver_threads=solver_threads)
    _, nominal, index = item
    start = time.perf_counter()
    parts = _segment_taylor_parts(nominal, index, ties, material, elements_through_thickness, step)
    with mkl_threads(solver_threads) if solver_threads else contextlib.nullcontext():
        arrays = cached(parts, lambda: _compute_segment_taylor(nominal, index, ties, elements_through_thickness, step),
                        cache_directory)
    return {"key": segment_taylor_key(nominal, index, ties, material,
                                      elements_through_thickness=elements_through_thickness, step=step),
            **arrays, "wall_s": time.perf_counter() - start}


# what one derivative job may hold at once (``fem_provider.plan_local_builds``): every parity class's
# factors, forward substitutions and +- assemblies together; two side by side put table1's cold
# main job at 4.5-4.8 GiB against 1.2 GiB with the builds (session 40), ~2.2 GB each
TAYLOR_MEMORY_BYTES = 2.5e9

# a segment's Taylor jobs, longest first (so the batch's end leaves no core idle long): the leaf
# segments [m1, s0] and [0, m1] (4 dimensions each, ~20-30 s on the prototype's grid) before the strut
# (the length alone, ~1 s); measured on table1's L1 and D1 (session 40)
_TAYLOR_ORDER = (1, 0, 2)


def build_segment_taylors(nominals: Iterable[FlexureChain], ties: str, material: Material = STEEL, *,
                          elements_through_thickness: float, cache_directory=None, step: float | None = None,
                          chains: Iterable[FlexureChain] = (), workers: int | None = None,
                          scheduler: str | None = None, progress: bool = True) -> int:
    """Compute the missing ``segment_taylors`` entries of ``nominals`` (one job per distinct
    segment) and build the missing tied ``chains`` (``tied_chains.tied_chain_matrices``) in one
    batch on the shared executor (``fem_provider.build_missing``), into the cache; returns how
    many were computed."""
    from flexcal.fem.condense_taylor import DERIVATIVE_STEP

    from .fem_provider import build_missing
    from .tied_chains import tied_chain_key

    step = DERIVATIVE_STEP if step is None else step
    jobs = []
    for nominal in dict.fromkeys(nominals):
        steps = sorted(_distinct_steps(nominal, ties).values(),
                       key=lambda i: _TAYLOR_ORDER.index(i) if i in _TAYLOR_ORDER else len(_TAYLOR_ORDER))
        jobs += [(segment_taylor_key(nominal, index, ties, material, elements_through_thickness=elements_through_thickness,
                                     step=step), ("taylor", nominal, index)) for index in steps]
    # longest first: every design's leaf segments, the chains (~6-8 s), the struts
    leaves, struts = [job for job in jobs if job[1][2] != 2], [job for job in jobs if job[1][2] == 2]
    built = [(tied_chain_key(chain, ties, material, elements_through_thickness=elements_through_thickness),
              ("chain", chain)) for chain in dict.fromkeys(chains)]
    missing = dict(leaves + built + struts)
    options = {"ties": ties, "material": material, "elements_through_thickness": float(elements_through_thickness),
               "step": float(step), "cache_directory": None if cache_directory is None else str(cache_directory)}

    def describe(item):
        if item[0] == "chain":
            return f"tied chain ({ties}) of a {item[1].length * 1e3:.1f} mm chain"
        return f"segment derivatives ({ties}) of a {item[1].length * 1e3:.1f} mm chain, step {item[2]}"

    return build_missing(missing, build_segment_taylor_job, options,
                         lambda item: ("stiffness", "segments") if item[0] == "chain" else
                         ("value", "parameters", "first", "second"),
                         describe, workers=workers, scheduler=scheduler, progress=progress,
                         cache_directory=cache_directory, in_threads=True, task_prefix="fem-segment-taylor",
                         what="segment derivatives and tied chains", job_bytes=TAYLOR_MEMORY_BYTES)


def taylor_tied_provider(provider, nominal_chains: Iterable[FlexureChain], *, reach: float = TAYLOR_REACH):
    """``provider`` (a tied one: ``tied_chains.tied_fem_provider``) whose moves of
    ``nominal_chains`` (``relative_dimensions``) come from their segments' derivatives
    (``taylor_chain_matrices``; module docstring), as do ``nominal_chains`` themselves and their
    rounding twins (the polynomials at r = 0; a nominal chain's is its build to the bit); every
    other chain is ``provider``'s (one chain build fewer per design and twin, 5-7 s of CPU each on
    the reference mount: the moves need the polynomials anyway).
    ``prepare_chains`` computes the missing derivatives (one job per distinct segment of each
    nominal chain asked for or moved) and builds the other chains."""
    from .segments import is_tied

    if not is_tied(provider):
        raise ValueError("the derivative provider wraps a tied provider (tied_chains.tied_fem_provider)")
    nominals = list(dict.fromkeys(nominal_chains))
    through = provider.elements_through_thickness
    cache_directory = getattr(provider, "cache_directory", None)
    progress = getattr(provider, "progress", True)
    memo: dict = {}

    def taylors_of(nominal):
        if nominal not in memo:
            memo[nominal] = segment_taylors(nominal, provider.ties, elements_through_thickness=through,
                                            cache_directory=cache_directory)
        return memo[nominal]

    moved_memo: dict = {}

    def matrices(chain):
        found = relative_dimensions(chain, nominals, reach)
        if found is None:
            return {"stiffness": provider.chain_stiffness(chain), "segments": provider.chain_segments(chain)}
        if chain not in moved_memo:
            start = time.perf_counter()
            moved_memo[chain] = taylor_chain_matrices(chain, found[0], taylors_of(found[0]), provider.ties)
            if progress and time.perf_counter() - start > 0.5:
                print(f"  FEM tied chain from segment derivatives: {time.perf_counter() - start:.1f} s",
                      file=sys.stderr)
        return moved_memo[chain]

    def prepare_chains(chains):
        chains = list(dict.fromkeys(chains))
        moved = [relative_dimensions(c, nominals, reach) for c in chains]
        designs = list(dict.fromkeys(found[0] for found in moved if found is not None))
        others = [c for c, found in zip(chains, moved) if found is None]
        if provider.scheduler is None and provider.workers == 0:
            return 0  # built lazily, in order, by the calls that follow
        # the Taylor jobs and the other chains' builds in one batch: no core idle between two
        return build_segment_taylors(designs, provider.ties, elements_through_thickness=through,
                                     cache_directory=cache_directory, chains=others, workers=provider.workers,
                                     scheduler=provider.scheduler, progress=progress)

    def wrapped(chain, x_start, x_end):
        return provider(chain, x_start, x_end)

    for name in ("elements_through_thickness", "mesher", "workers", "scheduler", "ties", "on_grid", "prepare",
                 "material", "cache_directory", "progress"):
        if hasattr(provider, name):
            setattr(wrapped, name, getattr(provider, name))
    wrapped.chain_stiffness = lambda chain: matrices(chain)["stiffness"]
    wrapped.chain_segments = lambda chain: matrices(chain)["segments"]
    wrapped.prepare_chains = prepare_chains
    wrapped.keeping_segments = lambda: wrapped
    wrapped.difference_steps = {symbol: DIFFERENCE_STEP for symbol in _symbols()}
    wrapped.description = provider.description + " (moved chains from the nominal segments' derivatives)"
    return wrapped
