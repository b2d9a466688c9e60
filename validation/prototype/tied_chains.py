"""A chain's five segments joined through section fields at its four cuts, for the virtual
prototype's frame: one 30 x 30 stiffness on the segments' deformation twists (issue 26, an
option; docs/meshing.md, "Session 24: the tied-cut frame").

The prototype's default joins its segments rigidly at the cuts m1, s0, s1, m2; that makes the
whole chains 19-23 % too stiff axially (docs/meshing.md, "Session 24: ties at every cut").
With ``ties="d12/p8"`` each segment is condensed onto order-12 distributing fields at m1, m2
and order-8 kinematic ones at s0, s1 (the strut segment [s0, s1] meshed with every cell split
into ``TIED_STRUT_REFINEMENT``^3 so its 2 x 2-cell section can carry them), the fields split
into the section bodies' rigid motions and the cuts' warping, the warping condensed
(``flexcal.fem.cut_warping``): K_chain (30, 30), cached per chain under a key with the ties,
together with the segments' 12 x 12 from the same condensations (the fields held rigid), so the
tied prototype needs no rigidly tied segment. With ``keep_segments`` (the model's slopes and
curvatures: ``segments.sharing_segments``) each segment's condensation is cached too, keyed
on its solid (its pieces, the chain's length) and ties, so a chain that shares a segment with one
built before (the slopes' moved chains) condenses only the rest (session 26, docs/scale.md); the
prototype's own chains (truth, budget, sweeps) share none and leave them out (session 27). The
missing chains are built on the executor's job threads (``build_tied_chains``; docs/meshing.md,
"Cost, session 24 (cost26)").
"""

from __future__ import annotations

import sys
import time
from typing import Any, Iterable

import numpy as np

from flexcal.geometry.params import STEEL, FlexureChain, Material

__all__ = ["TIES", "DEFAULT_TIES", "TIED_STRUT_REFINEMENT", "cut_interfaces", "tied_chain_key",
           "tied_chain_matrices", "tied_segment_keys", "tied_chain_stiffness", "build_tied_chain_job",
           "build_tied_chains", "tied_fem_provider"]

# "m/s": the interface at the mid-connector cuts m1, m2, then at the strut cuts s0, s1
# (chain_cuts.cut_coupling's labels; "d12": all four). d12/p8 and d12/d8 brought the whole
# L1 and D1 chains within 0.073 % / 0.055 % of their one piece; d12 at all four within
# 0.093 % (docs/meshing.md, "Session 24: ties at every cut")
TIES = ("d12/p8", "d12/d8", "d12")
DEFAULT_TIES = "d12/p8"
# every cell of the strut segment split into 3^3: 13 x 13 face nodes at s0, s1 (2 x 2 cells as
# meshed today cannot carry an order-8 field: its Gram matrix is singular there)
TIED_STRUT_REFINEMENT = 3


def cut_interfaces(ties: str) -> tuple[str, str, str, str]:
    """The interface labels at the cuts (m1, s0, s1, m2) of a ``ties`` label (``TIES``)."""
    if ties not in TIES:
        raise ValueError(f"unknown ties {ties!r}: use one of {', '.join(TIES)}")
    middle, strut = ties.split("/") if "/" in ties else (ties, ties)
    return (middle, strut, strut, middle)


# the modules of flexcal.validation whose code computes a tied chain's cache entry (its key's "code",
# as ``fem_provider.SEGMENT_CODE``): this one and the condensations' (``cut_fields.CONDENSATION_CODE``)
TIED_CHAIN_CODE = ("flexcal.validation.prototype.tied_chains", "flexcal.validation.prototype.cut_fields",
                   "flexcal.validation.prototype.fem_provider", "flexcal.validation.prototype.segments")


def _tied_chain_parts(chain: FlexureChain, ties: str, material: Material, elements_through_thickness: float) -> dict:
    """The cache key's parts of ``tied_chain_matrices``."""
    from flexcal.fem.cache import sources_digest
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS

    if material != STEEL:
        raise ValueError("tied chains are condensed in STEEL only (cut_fields' condensations); use the provider fem")
    # "tied_chain_matrices": K_chain and the segments' 12 x 12 (session 24's "tied_chain_stiffness"
    # entries held K_chain alone)
    return {"kind": "tied_chain_matrices", "code": sources_digest(*TIED_CHAIN_CODE), "chain": chain,
            "material": material, "ties": list(cut_interfaces(ties)),
            "mesh": {"mesher": "mapped", "elements_through_thickness": float(elements_through_thickness),
                     "options": PROTOTYPE_CHAIN_OPTIONS, "strut_refinement": TIED_STRUT_REFINEMENT,
                     "mirrored": True}}


def tied_chain_key(chain: FlexureChain, ties: str = DEFAULT_TIES, material: Material = STEEL, *,
                   elements_through_thickness: float) -> str:
    """The FEM cache key of ``tied_chain_matrices``."""
    from flexcal.fem.cache import cache_key

    return cache_key(_tied_chain_parts(chain, ties, material, elements_through_thickness))


def tied_chain_matrices(chain: FlexureChain, ties: str = DEFAULT_TIES, material: Material = STEEL, *,
                        elements_through_thickness: float, cache_directory=None,
                        keep_segments: bool = False) -> dict[str, np.ndarray]:
    """{"stiffness": K_chain (30, 30), "segments": (5, 12, 12)} [SI] of ``chain`` from one set of
    condensations, cached (``flexcal.fem.cache``): K_chain on its five segments' twists (module
    docstring) and each segment's 12 x 12 on its end sections' rigid motions with the cuts' fields
    held rigid (``flexcal.fem.cut_warping.rigid_part_stiffness``; chain order, chain frame, as
    the provider's ``(chain, x_start, x_end)`` gives them). Each segment on the prototype's grid
    (``PROTOTYPE_CHAIN_OPTIONS``, ``elements_through_thickness`` asked for; the strut segment refined).

    keep_segments: each of the chain's three distinct condensations is read from and kept in the
    cache as an entry of its own too (``cut_fields.interface_condensed`` with ``cache``, keyed on
    the segment's pieces, its chain's length, cut ends, labels, field scale, grid and material:
    ``interface_condensation_parts``), so a chain that shares a segment with one built before
    reads it (the matrices are the same to the bit either way; without, the 2.5 MB of segment
    entries of a chain that shares none is not written: docs/scale.md, "Issue 26, session 27"):
    the slopes' moved chains share the nominal chain's strut when w, a, t1 or t2 move, its
    [m1, s0] when t1 moves and its [0, m1] when t2 moves (L1 and D1 of table1;
    ``runs.model_correction.unchanged_slices``), the same bits as condensed again
    (tests/test_tied_chain_builds.py). Two job threads that need one segment at once compute it
    once (``flexcal.fem.cache.cached``)."""
    from flexcal.fem.cache import cached

    parts = _tied_chain_parts(chain, ties, material, elements_through_thickness)

    def compute() -> dict[str, np.ndarray]:
        from flexcal.fem.cut_warping import chain_twist_stiffness, rigid_part_stiffness

        from .cut_fields import chain_order_matrices, cut_orders, interface_condensed

        plan, interfaces, options, scale = _tied_plan(chain, ties)
        # keep_segments: each segment's condensation its own cache entry, so a moved chain's slice
        # that the dimension leaves as it was reads the nominal chain's (docs/scale.md, "Issue 26,
        # session 26")
        condensed = interface_condensed(plan, interfaces, elements_through_thickness, options, None, scale,
                                        cache=keep_segments, cache_directory=cache_directory)
        matrices, orders = chain_order_matrices(plan, condensed, interfaces), cut_orders(plan, interfaces)
        return {"stiffness": chain_twist_stiffness(matrices, orders, scale),
                "segments": rigid_part_stiffness(matrices, orders, scale)}

    return cached(parts, compute, cache_directory)


def _tied_plan(chain: FlexureChain, ties: str) -> tuple[list, tuple, dict, float]:
    """(plan, cut labels, grid options, field scale [m]) of ``tied_chain_matrices``: the chain's
    five segments (``cut_fields.interface_segments``), ``cut_interfaces(ties)``, the prototype's
    grid with the strut refined, ``interface_scale``."""
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS

    from .cut_fields import interface_scale, interface_segments

    # the grid's own strut knob (it splits only the leafless strut segment's cells), at least
    # TIED_STRUT_REFINEMENT: one knob, not a refinement on top of the grid's
    options = {**PROTOTYPE_CHAIN_OPTIONS,
               "strut_refinement": max(PROTOTYPE_CHAIN_OPTIONS.get("strut_refinement", 1), TIED_STRUT_REFINEMENT)}
    return interface_segments(chain, 5), cut_interfaces(ties), options, interface_scale(chain, 5)


def tied_segment_keys(chain: FlexureChain, ties: str = DEFAULT_TIES, *, elements_through_thickness: float) -> dict:
    """{``cut_fields.plan_key``: FEM cache key}: the cache entries of ``chain``'s distinct segment
    condensations in ``tied_chain_matrices`` (``cut_fields.interface_condensation_parts``), in
    chain order ([0, m1], [m1, s0], [s0, s1]); two chains share an entry where the keys are equal."""
    from flexcal.fem.cache import cache_key

    from .cut_fields import interface_condensation_parts, interface_condensations

    plan, interfaces, options, scale = _tied_plan(chain, ties)
    return {key: cache_key(interface_condensation_parts(segment, starts, ends, labels, scale,
                                                        elements_through_thickness, options))
            for key, (segment, starts, ends, labels) in interface_condensations(plan, interfaces).items()}


def tied_chain_stiffness(chain: FlexureChain, ties: str = DEFAULT_TIES, material: Material = STEEL, *,
                         elements_through_thickness: float, cache_directory=None) -> np.ndarray:
    """K_chain (30, 30) [SI] of ``chain`` (``tied_chain_matrices``)."""
    return tied_chain_matrices(chain, ties, material, elements_through_thickness=elements_through_thickness,
                               cache_directory=cache_directory)["stiffness"]


def build_tied_chain_job(chain: FlexureChain, *, ties: str, material: Material, elements_through_thickness: float,
                         cache_directory=None, keep_segments: bool = False, mesher_threads: int = 0,
                         solver_threads: int = 0) -> dict[str, Any]:
    """One chain's ``tied_chain_matrices`` on a job thread or worker: {"key": its cache key
    there, the matrices, "wall_s": [s]}; its cache gets the entry too; PARDISO on
    ``solver_threads`` MKL threads of the calling thread (0: all cores;
    ``flexcal.fem.solve.solver_threads``). mesher_threads: unused (``build_missing`` hands it to
    every job; the mapped mesher runs on the calling thread)."""
    import contextlib

    from flexcal.fem.solve import solver_threads as mkl_threads

    start = time.perf_counter()
    with mkl_threads(solver_threads) if solver_threads else contextlib.nullcontext():
        matrices = tied_chain_matrices(chain, ties, material, elements_through_thickness=elements_through_thickness,
                                       cache_directory=cache_directory, keep_segments=keep_segments)
    return {"key": tied_chain_key(chain, ties, material, elements_through_thickness=elements_through_thickness),
            **matrices, "wall_s": time.perf_counter() - start}


def build_tied_chains(chains: Iterable[FlexureChain], ties: str = DEFAULT_TIES, material: Material = STEEL, *,
                      elements_through_thickness: float, cache_directory=None, keep_segments: bool = False,
                      workers: int | None = None, scheduler: str | None = None, progress: bool = True) -> int:
    """Build the ``tied_chain_matrices`` (with ``keep_segments``) of ``chains`` that the cache lacks, on the shared
    executor (``fem_provider.build_missing``), into the cache; returns how many were built.
    workers: local job threads (``plan_local_builds``; 0: this process, one after the other);
    scheduler: a Dask scheduler address. Threads, as today's segments: ~70 % of a chain is
    PARDISO, which runs outside the interpreter lock, and the mapped meshing ~1 %. Cold table1
    seed 1 at load ~1.3: 2 threads 26 s wall for 47 s CPU, this process 48 s for 48 s; worker
    processes cost ~10 s more CPU (Dask, the imports) (docs/meshing.md, "Cost, session 24
    (cost26)"). The same matrices as built here one after the other, to the bit, with PARDISO on
    as many threads (tests/test_tied_chain_builds.py)."""
    from .fem_provider import build_missing

    missing = {tied_chain_key(chain, ties, material, elements_through_thickness=elements_through_thickness): chain
               for chain in chains}
    options = {"ties": ties, "material": material, "elements_through_thickness": float(elements_through_thickness),
               "cache_directory": None if cache_directory is None else str(cache_directory),
               "keep_segments": bool(keep_segments)}
    return build_missing(missing, build_tied_chain_job, options, ("stiffness", "segments"),
                         lambda chain: f"tied chain ({ties}) of a {chain.length * 1e3:.1f} mm chain",
                         workers=workers, scheduler=scheduler, progress=progress, cache_directory=cache_directory,
                         in_threads=True, task_prefix="fem-tied-chain", what="tied chains")


def tied_fem_provider(ties: str = DEFAULT_TIES, *, keep_segments: bool = False, **fem_options):
    """``fem_provider(**fem_options)`` (the mapped mesher: its ``(chain, x_start, x_end)`` and
    ``prepare`` stay the rigidly tied segments', for the model's corrections and anything else
    that asks for a slice) that also gives, per chain, from one set of condensations
    (``tied_chain_matrices``): ``provider.chain_stiffness(chain)``, the chain's 30 x 30 on its
    segments' twists joined through the ``ties`` fields, which ``build_prototype`` then uses in
    the frame, and ``provider.chain_segments(chain)``, its five 12 x 12 with the cut fields held
    rigid (``rigid_part_stiffness``), which ``build_prototype`` stores as the K_jj instead of
    building the rigid segments too. ``provider.prepare_chains(chains)`` builds the missing
    chains on the executor (``build_tied_chains``; ``workers=0``: none, each chain is built at
    its first call). keep_segments: the chains' segment condensations kept as cache entries of
    their own (``tied_chain_matrices``), for the model's corrections, whose moved chains share
    them (``segments.sharing_segments``: ``provider.keeping_segments()``, the same provider with
    keep_segments); the prototype's chains (truth, the error budget, sweeps) share none and
    leave them out."""
    from .fem_provider import DEFAULT_ELEMENTS_THROUGH, fem_provider

    cut_interfaces(ties)  # refused here if unknown
    if fem_options.get("mesher", "mapped") != "mapped":
        raise ValueError(f"ties={ties!r} need the mapped mesher (the fields' faces), not {fem_options['mesher']!r}")
    provider = fem_provider(**fem_options)
    material = fem_options.get("material", STEEL)
    through = fem_options.get("elements_through_thickness", DEFAULT_ELEMENTS_THROUGH)
    cache_directory, progress = fem_options.get("cache_directory"), fem_options.get("progress", True)

    def matrices(chain: FlexureChain) -> dict[str, np.ndarray]:
        start = time.perf_counter()
        out = tied_chain_matrices(chain, ties, material, elements_through_thickness=through,
                                  cache_directory=cache_directory, keep_segments=keep_segments)
        if progress and time.perf_counter() - start > 0.5:
            print(f"  FEM tied chain ({ties}) of a {chain.length * 1e3:.1f} mm chain: "
                  f"{time.perf_counter() - start:.1f} s", file=sys.stderr)
        return out

    def prepare_chains(chains: Iterable[FlexureChain]) -> int:
        if provider.scheduler is None and provider.workers == 0:
            return 0  # built lazily, in order, by the calls that follow
        return build_tied_chains(chains, ties, material, elements_through_thickness=through,
                                 cache_directory=cache_directory, keep_segments=keep_segments, workers=provider.workers,
                                 scheduler=provider.scheduler, progress=progress)

    def keeping_segments():
        return provider if keep_segments else tied_fem_provider(ties, keep_segments=True, **fem_options)

    def on_grid(n: float):
        """This provider (same ties, material, cache, executor) with ``n`` elements through the
        thinnest section, for the model's dimension terms measured on another grid
        (``model_correction.slope_provider``; their own cache keys)."""
        return tied_fem_provider(ties, keep_segments=keep_segments,
                                 **{**fem_options, "elements_through_thickness": float(n)})

    provider.prepare_chains, provider.ties, provider.keeping_segments = prepare_chains, ties, keeping_segments
    provider.on_grid = on_grid
    provider.chain_stiffness = lambda chain: matrices(chain)["stiffness"]
    provider.chain_segments = lambda chain: matrices(chain)["segments"]
    provider.description = provider.description[:-1] + f", cuts tied through {ties} fields)"
    return provider
