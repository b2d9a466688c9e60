"""The virtual prototype's FEM stiffness provider: each chain segment (``ChainSegment``)
is built as a CadQuery solid, meshed with quadratic tets and condensed onto its two
section reference points (12 x 12, chain frame, SI), through the content-addressed cache
of ``flexcal.fem.cache`` so a segment solved once is never solved again.

Symmetry: a chain is mirror-symmetric about its middle; the segment [L - b, L - a] is
the segment [a, b] turned by pi about the local z axis (x -> -x, y -> -y), a proper
rotation. Its stiffness is that rotation applied to both nodes' twists, with the nodes
swapped, so only the first half of a chain (and the strut) is ever meshed.

Parallel builds: ``fem_provider(workers=..., scheduler=...)`` gives the provider a
``prepare(slices)`` hook that ``build_prototype`` and ``compliance_factors`` call with
every slice they are about to ask for; the segments missing from the cache are then
built at once on the shared executor (``flexcal.validation.executor``: threads of this
process or a Dask cluster), each under the same cache key as a sequential build, and
the provider's calls that follow are all cache hits (``build_segments``). They are handed
out longest first (``segment_build_cost``: leaf segments, thinnest leaves first, then the
cheap strut segments), and a local job thread meshes and solves on its share of the cores
(``plan_local_builds``).
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from typing import Any, Callable, Iterable

import numpy as np

from flexcal.geometry.params import STEEL, ChainSegment, FlexureChain, Material

__all__ = ["fem_provider", "segment_stiffness_fem", "mirror_segment_stiffness", "DEFAULT_ELEMENTS_THROUGH",
           "canonical_segment", "segment_cache_key", "build_segments", "build_segment_job", "segment_build_cost",
           "plan_local_builds", "BUILD_MEMORY_BYTES", "DEFAULT_MESHER", "MESHERS", "TETWILD_ELEMENTS_THROUGH"]

# 7 cells through the thinnest leaf section asked for (raised to 8 on the stubby L leaves,
# ``cells_through``) on the prototype's grid (``PROTOTYPE_CHAIN_OPTIONS``, session 16): every
# dominant entry of the 12 x 12 of the L1 and D1 leaf segments within 0.48 % of the Richardson
# limit of a nested reference sequence (session 13's fast grid at 6 through: 0.85 %), at
# 75k-86k DOF per leaf segment; docs/meshing.md, "The prototype's grid". Since session 17
# condensed on the mirror part of that grid (a quarter for the L leaf segments, a half for the
# D ones; MIRRORED below): L1 0.446 % / 0.448 %, D1 unchanged, 0.46x main's cold-truth CPU
# (docs/meshing.md, "The prototype's grid, mirrored"; docs/scale.md, session 17). The calibration
# model's FEM factors come from this same provider (validation/runs/model_correction.py),
# so they moved with it. Since session 20 with 8 cells per fillet arc (was 6): every dominant
# entry of the four leaf segments within 0.488 % of the Q2-hex reference limit (L1 [m1, s0]'s
# torsion was 0.506 %). fTetWild keeps its own default (TETWILD_ELEMENTS_THROUGH).
DEFAULT_ELEMENTS_THROUGH = 7
# 3 quadratic tets through the thinnest leaf section of a fTetWild mesh: within ~0.3 % of the
# converged bending compliance on the reference notch hinge after snapping (docs/meshing.md),
# at a third of the cost of 4; the leaf segment D1 [0, m1]: within 0.4 % of the mapped
# Richardson limit on every dominant entry.
TETWILD_ELEMENTS_THROUGH = 3
# "mapped": the deterministic multi-block mesher (flexcal.fem.mesh_mapped_chain), pure numpy,
# the same mesh on every machine; "tetwild": fTetWild on the CadQuery solid (repeatable
# only through the compiled seed, fem/_entropy.c).
MESHERS = ("mapped", "tetwild")
DEFAULT_MESHER = "mapped"
# the modules of flexcal.validation whose code computes a segment's cache entry: their sources are
# in its key (``flexcal.fem.cache.sources_digest``; flexcal.fem and flexcal.geometry are in every
# key already), so an edit of them is a new key, never a stale matrix
SEGMENT_CODE = ("flexcal.validation.prototype.fem_provider",)
_TURN_Z = np.diag([-1.0, -1.0, 1.0])  # rotation by pi about local z


def mirror_segment_stiffness(stiffness: np.ndarray) -> np.ndarray:
    """12 x 12 of the mirror image (turned by pi about z, nodes swapped) of a segment."""
    T = np.kron(np.eye(4), _TURN_Z)
    swap = np.block([[np.zeros((6, 6)), np.eye(6)], [np.eye(6), np.zeros((6, 6))]])
    P = swap @ T
    return P @ stiffness @ P.T


def _segment_parts(segment: ChainSegment, material: Material, elements_through_thickness: float,
                   mesher: str = DEFAULT_MESHER) -> dict:
    from flexcal.fem.cache import sources_digest
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS

    if mesher not in MESHERS:
        raise ValueError(f"mesher={mesher!r} must be one of {', '.join(MESHERS)}")
    return {"kind": "chain_segment_stiffness", "code": sources_digest(*SEGMENT_CODE), "segment": segment,
            "material": material,
            "mesh": {"mesher": mesher, "elements_through_thickness": float(elements_through_thickness),
                     **({"options": PROTOTYPE_CHAIN_OPTIONS, "mirrored": True} if mesher == "mapped" else {})}}


def segment_cache_key(segment: ChainSegment, material: Material = STEEL, *,
                      elements_through_thickness: float = DEFAULT_ELEMENTS_THROUGH,
                      mesher: str = DEFAULT_MESHER) -> str:
    """The FEM cache key of a segment's stiffness (``flexcal.fem.cache.cache_key``)."""
    from flexcal.fem.cache import cache_key

    return cache_key(_segment_parts(segment, material, elements_through_thickness, mesher))


def canonical_segment(chain: FlexureChain, x_start: float, x_end: float) -> tuple[ChainSegment, bool]:
    """(segment that is meshed, mirrored?) for the slice [x_start, x_end] [m] of ``chain``:
    a slice in the second half is the mirror image of one in the first (module docstring)."""
    length = chain.length
    # a slice starting at the middle (the cut at L/2) is the mirror image of the first half
    mirrored = x_start > 0.5 * length - 1e-12 and x_end > 0.5 * length + 1e-12
    a, b = (length - x_end, length - x_start) if mirrored else (x_start, x_end)
    # cut positions to 1 pm: L - (L - x) must find the same cache entry as x
    return ChainSegment(chain=chain, x_start=round(max(a, 0.0), 12), x_end=round(min(b, length), 12)), mirrored


# CadQuery's multimethod dispatch (Solid.extrudeLinear, ...) resolves its signatures on the
# first call and is not safe for two threads at once: a cold threaded build of the FEM
# goal test failed once with "DispatchError: ('extrudeLinear: 0 methods found', ...)" (session
# 11; a rerun passed). The solid is a fraction of a second of a segment's tens of seconds of
# meshing and solving, so building solids one thread at a time costs nothing measurable.
_CAD_LOCK = threading.Lock()


def segment_stiffness_fem(segment: ChainSegment, material: Material = STEEL, *,
                          elements_through_thickness: float = DEFAULT_ELEMENTS_THROUGH,
                          cache_directory=None, mesher_threads: int = 0, mesher: str = DEFAULT_MESHER) -> np.ndarray:
    """Condensed 12 x 12 stiffness [SI] of one chain segment between its end-face centres
    (node A at x_start, node B at x_end; DOF order ux, uy, uz, rx, ry, rz), cached.
    mesher: "mapped" (``flexcal.fem.mesh_mapped_chain``, no CAD solid needed) or "tetwild"
    (``MESHERS``); mesher_threads: fTetWild's threads (0: all cores; not part of the cache
    key: the seeded fTetWild gives the same mesh on any number of threads, docs/meshing.md)."""
    from flexcal.fem.cache import cached

    parts = _segment_parts(segment, material, elements_through_thickness, mesher)

    def compute() -> dict[str, np.ndarray]:
        from flexcal.fem.condense import chain_stiffness
        from flexcal.geometry.exact import end_planes, reference_points

        planes, points = end_planes(segment), reference_points(segment)
        if mesher == "mapped":
            # MIRRORED: the segment is symmetric about y = 0 and z = 0; its mapped mesh's part
            # on the non-negative side of the planes whose grid holds the exact 0, condensed
            # once per parity class (docs/meshing.md, "The prototype's grid, mirrored")
            from flexcal.fem.condense import mirrored_chain_stiffness
            from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS, mapped_mesh_chain_mirror_part

            part, axes = mapped_mesh_chain_mirror_part(segment, elements_through_thickness=elements_through_thickness,
                                                       **PROTOTYPE_CHAIN_OPTIONS)
            stiffness = mirrored_chain_stiffness(part, material, planes["A"], points["A"], planes["B"], points["B"],
                                                 axes)
            return {"stiffness": 0.5 * (stiffness + stiffness.T)}
        from flexcal.fem.mesh import mesh_part
        from flexcal.geometry.solids import segment_solid

        with _CAD_LOCK:
            part = segment_solid(segment)
        mesh, _report = mesh_part(part, elements_through_thickness=elements_through_thickness,
                                  num_threads=mesher_threads)
        stiffness = chain_stiffness(mesh, material, planes["A"], points["A"], planes["B"], points["B"])
        return {"stiffness": 0.5 * (stiffness + stiffness.T)}

    return cached(parts, compute, cache_directory)["stiffness"]


def segment_build_cost(segment: ChainSegment) -> float:
    """Relative cost of building ``segment`` (dimensionless), to hand the longest builds out
    first: a leaf meshed with a fixed number of quadratic tets through its thickness t has
    about (length x width) / t^2 of them, and the leaves' tets dominate meshing and solve;
    blocks, connectors and strut, meshed coarsely, count 0."""
    chain = segment.chain
    cost = 0.0
    for kind, a, b in segment.segments():
        if kind.startswith("leaf"):
            thickness = chain.thickness_1 if kind == "leaf1" else chain.thickness_2
            cost += (b - a) * chain.width / thickness ** 2
    return cost


# LOCAL_BUILDS_IN_THREADS: local parallel builds (--workers N, no --scheduler) run on N
# threads of this process, not on a LocalCluster of N processes: a segment's heavy work
# runs outside the interpreter lock (fTetWild in its child process, ~77 %; PARDISO, numpy),
# and N processes each imported CadQuery and the FEM stack again (2.0 s a process) and ran
# Dask beside the jobs. Measured, a cold table1 truth on 2 workers alone on the 2-core
# machine, 3 runs each (docs/scale.md, "Session 9"): processes 62.9-64.6 s wall for
# 123-126 s CPU, threads 59.0-62.6 s for 114-121 s CPU (two batches). A cluster given by
# address keeps its processes.
#
# Each local job thread owns its share of the cores, usable cores // threads (at least 1):
# fTetWild on that many threads and PARDISO on that many MKL threads
# (``flexcal.fem.solve.solver_threads``, that thread only), so N threads on N cores each
# mesh and solve on one. In this process (--workers 0) and on a cluster given by address,
# whose workers may own many cores, both keep all cores (0). Measured on the 2-core
# machine, one leaf segment of the mount meshed 4 times each way, alone: all cores median
# 6.1 s wall for 7.8 s CPU, one thread 6.4 s wall for 6.6 s CPU; the second thread bought
# 5 % of wall time for 17 % more CPU, which a busy second worker needs itself.
#
# BUILD_MEMORY_BYTES: what one segment build may hold at once, to cap the default number
# of threads by the free memory (an out-of-memory kill ends a run without a word). Measured
# on the mount's largest leaf segment (150 mm chain, 3 elements through): this process
# grew by 0.81 GB (maxrss 0.48 -> 1.29 GB), fTetWild's child peaked at 0.51 GB; 1.5 GB
# leaves ~15 % above that.
BUILD_MEMORY_BYTES = 1.5e9


def plan_local_builds(workers: int | None, n_missing: int, *, cores: int, available_bytes: float,
                      job_bytes: float = BUILD_MEMORY_BYTES) -> tuple[int, int]:
    """(job threads, cores each) for ``n_missing`` segment builds on this machine.

    workers: None (the command line's default): one thread per usable core, at most one
    per missing segment and per ``job_bytes`` (``BUILD_MEMORY_BYTES``) of free memory (at least 1);
    0: none (built one after the other in this process, all cores each); N > 0: N threads
    as asked. Each thread owns cores // threads of the cores (at least 1)."""
    from ..executor import resolve_workers

    threads = resolve_workers(workers, n_missing, cores=cores)
    if workers is None and threads:
        threads = max(1, min(threads, int(available_bytes // job_bytes)))
    return threads, max(1, cores // threads) if threads else 0


def build_segment_job(segment: ChainSegment, *, material: Material, elements_through_thickness: float,
                      cache_directory=None, mesher_threads: int = 0, solver_threads: int = 0,
                      mesher: str = DEFAULT_MESHER) -> dict[str, Any]:
    """One segment build on a worker: {"key": its cache key there, "stiffness": (12, 12),
    "wall_s": [s]}; the worker's cache gets the entry too (``segment_stiffness_fem``);
    fTetWild on ``mesher_threads`` threads and PARDISO on ``solver_threads`` MKL threads
    of the calling thread (0: all cores; ``flexcal.fem.solve.solver_threads``)."""
    from flexcal.fem.solve import solver_threads as mkl_threads

    start = time.perf_counter()
    with mkl_threads(solver_threads) if solver_threads else contextlib.nullcontext():
        stiffness = segment_stiffness_fem(segment, material, elements_through_thickness=elements_through_thickness,
                                          cache_directory=cache_directory, mesher_threads=mesher_threads,
                                          mesher=mesher)
    return {"key": segment_cache_key(segment, material, elements_through_thickness=elements_through_thickness,
                                     mesher=mesher),
            "stiffness": stiffness, "wall_s": time.perf_counter() - start}


def build_segments(slices: Iterable[tuple[FlexureChain, float, float]], material: Material = STEEL, *,
                   elements_through_thickness: float = DEFAULT_ELEMENTS_THROUGH, cache_directory=None,
                   workers: int | None = None, scheduler: str | None = None, progress: bool = True,
                   mesher: str = DEFAULT_MESHER) -> int:
    """Build the FEM segments of ``slices`` [(chain, x_start [m], x_end [m])] that the cache
    lacks, in parallel on the shared executor, into the cache; returns how many were built.

    workers: local job threads (``plan_local_builds``; None: one per usable core, at most
    one per missing segment and per ``BUILD_MEMORY_BYTES`` of free memory; 0: this
    process); scheduler: a Dask scheduler address. Each result is stored under the key a
    sequential build uses (``build_missing``).
    """
    wanted: dict[str, ChainSegment] = {}  # build_missing skips those already cached
    for chain, x_start, x_end in slices:
        segment, _ = canonical_segment(chain, float(x_start), float(x_end))
        key = segment_cache_key(segment, material, elements_through_thickness=elements_through_thickness,
                                mesher=mesher)
        wanted.setdefault(key, segment)
    options = {"material": material, "elements_through_thickness": float(elements_through_thickness),
               "cache_directory": None if cache_directory is None else str(cache_directory), "mesher": mesher}
    # longest first (stable): the cheap strut segments fill the gaps at the end instead of a
    # leaf segment started last keeping one worker busy while the others idle
    return build_missing(dict(sorted(wanted.items(), key=lambda item: segment_build_cost(item[1]), reverse=True)),
                         build_segment_job, options, ("stiffness",),
                         lambda segment: (f"segment [{segment.x_start * 1e3:.1f}, {segment.x_end * 1e3:.1f}] mm of a "
                                          f"{segment.chain.length * 1e3:.1f} mm chain"),
                         workers=workers, scheduler=scheduler, progress=progress, cache_directory=cache_directory,
                         in_threads=True, task_prefix="fem-segment", what="segments")


def build_missing(missing: dict[str, Any], job: Callable[..., dict[str, Any]], options: dict[str, Any],
                  arrays: tuple[str, ...] | Callable[[Any], tuple[str, ...]], describe: Callable[[Any], str], *,
                  workers: int | None,
                  scheduler: str | None, progress: bool, cache_directory, in_threads: bool, task_prefix: str,
                  what: str, job_bytes: float = BUILD_MEMORY_BYTES) -> int:
    """Run ``job(item, **options, mesher_threads=n, solver_threads=n)`` (n: each local job's
    share of the cores, ``plan_local_builds``; 0: all) for each of ``missing``
    ({cache key: item}, in the order handed out; those already cached are skipped) on the shared
    executor and store each result's ``arrays`` (names, or item -> names for a batch of several
    kinds) under its key; returns how many were built.

    workers / scheduler as ``build_segments``; job_bytes: what one job may hold at once
    (``plan_local_builds``); in_threads: local jobs on threads of this process
    (``LOCAL_BUILDS_IN_THREADS``), else on worker processes. A job returns {"key": its cache key
    there, the arrays, "wall_s": [s]}; the worker's own cache write makes the store a no-op on
    shared storage, a remote worker without it hands the arrays back, and a cache folder that
    cannot be written keeps them in this process's memory (``flexcal.fem.cache.keep_cached``). A
    worker whose flexcal code differs (other cache key) is an error: its result is not this
    version's."""
    from flexcal.fem.cache import cache_is_writable, keep_cached, load_cached

    from ..blas_threads import blas_threads
    from ..executor import run_jobs, usable_cores, where

    cache_is_writable(cache_directory)  # up front: an unwritable cache warns once, before any FEM work
    missing = {key: item for key, item in missing.items() if load_cached(key, cache_directory) is None}
    if not missing:
        return 0
    if scheduler is None:
        import psutil

        n_workers, cores_each = plan_local_builds(workers, len(missing), cores=usable_cores(),
                                                  available_bytes=psutil.virtual_memory().available,
                                                  job_bytes=job_bytes)
    else:
        n_workers, cores_each = 0, 0  # the cluster's workers keep their cores
    in_threads = in_threads and n_workers > 0  # LOCAL_BUILDS_IN_THREADS
    log = (lambda text: print(text, file=sys.stderr, flush=True)) if progress else (lambda text: None)
    log(f"  FEM {what}: {len(missing)} to build on {where(n_workers, scheduler, in_threads)}")
    start, built = time.perf_counter(), []
    keys = {id(item): key for key, item in missing.items()}

    def on_done(item: Any, result: dict[str, Any]) -> None:
        key = keys[id(item)]
        if result["key"] != key:
            raise RuntimeError("a Dask worker runs another flexcal version (its FEM cache key differs); install the "
                               "same flexcal on the workers as on this machine")
        if load_cached(key, cache_directory) is None:  # an unwritable cache keeps it in memory (warned once)
            names = arrays(item) if callable(arrays) else arrays
            keep_cached(key, {name: result[name] for name in names}, cache_directory)
        built.append(key)
        log(f"  FEM {describe(item)}: {result['wall_s']:.1f} s ({len(built)}/{len(missing)}, "
            f"{time.perf_counter() - start:.0f} s elapsed)")

    # the jobs write into the same folder when it is shared (threads of this process: always).
    # Job threads side by side hold the dense BLAS (OpenBLAS's pools) to their share of the cores:
    # PARDISO runs on each job's own (solver_threads), but the products beside it (a condensation's
    # Y^T Y, the cut fields' least squares) ran on every core from every job thread, four BLAS
    # threads on 2 cores. Cold table1 truth 32.5 -> 25.6 s wall, 61.7 -> 48.1 s CPU (docs/scale.md,
    # "Issue 26, session 30"). The pools are the process's, held while this thread waits. At one
    # thread whatever the batch's size (session 36): a job's entry then holds the same bits built
    # alone or beside others, on any core count (``flexcal.fem.solve.one_thread``, which holds
    # each job's PARDISO at one thread too).
    with blas_threads(1) if in_threads else contextlib.nullcontext():
        failures = run_jobs(list(missing.values()), job, on_done, key=lambda item: keys[id(item)][:16],
                            workers=n_workers, scheduler=scheduler,
                            job_options={**options, "mesher_threads": cores_each, "solver_threads": cores_each},
                            task_prefix=task_prefix, in_threads=in_threads)
    if failures:
        key, text = next(iter(failures.items()))
        raise RuntimeError(f"{len(failures)} FEM build(s) of {what} failed, e.g. {text}; the {len(built)} finished "
                           "one(s) are cached, run the same command again to retry (--workers 0 builds them "
                           "in this process)")
    return len(built)


def fem_provider(material: Material = STEEL, *, elements_through_thickness: float = DEFAULT_ELEMENTS_THROUGH,
                 cache_directory=None, progress: bool = True, workers: int | None = 0,
                 scheduler: str | None = None,
                 mesher: str = DEFAULT_MESHER) -> Callable[[FlexureChain, float, float], np.ndarray]:
    """A provider ``(chain, x_start, x_end) -> (12, 12)`` for ``build_prototype``.

    workers / scheduler: where ``provider.prepare(slices)`` builds the missing segments
    (``build_segments``); the default ``workers=0`` without a scheduler builds them one
    after the other in this process as the provider is called (the command line's
    default, ``--workers`` not given, is None: one thread per usable core,
    ``plan_local_builds``). mesher: "mapped" (default) or "tetwild" (``MESHERS``).
    """
    if mesher not in MESHERS:  # refused here, not at the first segment
        raise ValueError(f"mesher={mesher!r} must be one of {', '.join(MESHERS)}")

    def provider(chain: FlexureChain, x_start: float, x_end: float) -> np.ndarray:
        segment, mirrored = canonical_segment(chain, x_start, x_end)
        start = time.perf_counter()
        stiffness = segment_stiffness_fem(segment, material, elements_through_thickness=elements_through_thickness,
                                          cache_directory=cache_directory, mesher=mesher)
        if progress and time.perf_counter() - start > 0.5:
            print(f"  FEM segment [{segment.x_start * 1e3:.1f}, {segment.x_end * 1e3:.1f}] mm of a "
                  f"{chain.length * 1e3:.1f} mm chain: {time.perf_counter() - start:.1f} s", file=sys.stderr)
        return mirror_segment_stiffness(stiffness) if mirrored else stiffness

    def prepare(slices: Iterable[tuple[FlexureChain, float, float]]) -> int:
        if scheduler is None and workers == 0:
            return 0  # built lazily, in order, by the calls that follow
        return build_segments(slices, material, elements_through_thickness=elements_through_thickness,
                              cache_directory=cache_directory, workers=workers, scheduler=scheduler,
                              progress=progress, mesher=mesher)

    def on_grid(n: float):
        """This provider (same material, cache, executor, mesher) with ``n`` elements through
        the thinnest section: what the compliance slopes are measured with (their own cache keys)."""
        return fem_provider(material, elements_through_thickness=n, cache_directory=cache_directory,
                            progress=progress, workers=workers, scheduler=scheduler, mesher=mesher)

    provider.prepare = prepare
    provider.on_grid = on_grid
    provider.mesher = mesher
    # what the compliance slopes' own cached jobs need (validation/runs/model_correction.py)
    provider.material, provider.cache_directory = material, cache_directory
    provider.workers, provider.scheduler, provider.progress = workers, scheduler, progress
    provider.elements_through_thickness = float(elements_through_thickness)
    provider.description = (f"FEM (quadratic tets, {mesher} mesh, {elements_through_thickness:g} through the thinnest "
                            f"section)")
    return provider
