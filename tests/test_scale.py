"""The shared executor (``flexcal.validation.executor``) under the heavy jobs: FEM segment
builds of the virtual prototype, ``diagnose-benchmark`` cases, ``compensate``'s bench
(issue #14, docs/scale.md). The cluster tests start a real ``dask scheduler`` and two
``dask worker`` processes on localhost."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from flexcal.fem.cache import load_cached, store_cached
from flexcal.geometry.params import reference_mechanism
from flexcal.validation import cli
from flexcal.validation.executor import resolve_workers, run_jobs
from flexcal.validation.prototype.fem_provider import (DEFAULT_ELEMENTS_THROUGH, build_segments, canonical_segment, fem_provider, segment_cache_key)
from flexcal.validation.prototype.mechanism import build_prototype
from flexcal.validation.prototype.segments import analytic_provider, chain_slices, section_nodes

# `dask scheduler` / `dask worker` through this interpreter: the `dask` script's shebang may
# name another environment's Python (a copied virtualenv), which imports another flexcal
SCHEDULER = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
WORKER = [sys.executable, "-m", "distributed.cli.dask_worker"]


def _fail_on_three(item):
    if item == 3:
        raise ValueError("three is bad")
    return item * item


def test_run_jobs_in_process_hands_each_result_over_and_lists_failures():
    done = {}
    failures = run_jobs([1, 2, 3, 4], _fail_on_three, lambda item, result: done.update({item: result}), key=str,
                        workers=0)
    assert done == {1: 1, 2: 4, 4: 16}
    assert failures == {"3": "ValueError: three is bad"}
    assert resolve_workers(None, 0) == 0 and resolve_workers(None, 1) == 1 and resolve_workers(0, 9) == 0
    assert resolve_workers(None, 100) == len(os.sched_getaffinity(0))  # the cores this process may use
    with pytest.raises(ValueError, match="--workers=-1 must be >= 0"):
        resolve_workers(-1, 3)


def test_run_jobs_in_threads_runs_side_by_side_and_lists_failures():
    done = {}
    failures = run_jobs([1, 2, 3, 4], _fail_on_three, lambda item, result: done.update({item: result}), key=str,
                        workers=2, in_threads=True)
    assert done == {1: 1, 2: 4, 4: 16} and failures == {"3": "ValueError: three is bad"}
    # side by side: two jobs that each wait for the other to start finish only together
    import threading

    barrier = threading.Barrier(2, timeout=10)
    assert run_jobs(["a", "b"], lambda item: barrier.wait(), lambda item, result: None, key=str, workers=2,
                    in_threads=True) == {}


def _wait_on_a_child(item):
    if item == "quick":
        return None
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    _wait_on_a_child.children.append(child)
    child.wait()
    raise RuntimeError(f"child ended with {child.returncode}")


def test_run_jobs_in_threads_stopped_kills_the_running_jobs_children():
    """Ctrl-C (here: raised by the first result's hand-over) while another job waits on its
    child process: the child is killed at once and the job fails."""
    _wait_on_a_child.children = []

    def on_done(item, result):
        while not _wait_on_a_child.children:  # the other job's child is running
            time.sleep(0.01)
        raise KeyboardInterrupt

    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        run_jobs(["slow", "quick"], _wait_on_a_child, on_done, key=str, workers=2, in_threads=True)
    (child,) = _wait_on_a_child.children
    assert child.wait(timeout=10) == -9  # SIGKILL, long before its 60 s
    assert time.monotonic() - start < 10


def _start_a_child_later(item):
    if item == "quick":
        return None
    _start_a_child_later.interrupted.wait(10)  # busy elsewhere (Python, PARDISO) when the interrupt came
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    _start_a_child_later.children.append(child)
    child.wait()
    raise RuntimeError(f"child ended with {child.returncode}")


def test_a_child_started_after_the_interrupt_is_killed_too():
    """A job that was not waiting on a child when the run was abandoned starts its next one
    afterwards: before, that child ran to its end (a whole mesh) and the command's exit
    waited for it; now it is killed and the interrupt comes through once the job ends."""
    import threading

    _start_a_child_later.children = []
    _start_a_child_later.interrupted = threading.Event()

    def on_done(item, result):
        _start_a_child_later.interrupted.set()
        raise KeyboardInterrupt

    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        run_jobs(["slow", "quick"], _start_a_child_later, on_done, key=str, workers=2, in_threads=True)
    (child,) = _start_a_child_later.children  # run_jobs returned only after the job had ended
    assert child.returncode == -9  # SIGKILL, long before its 60 s
    assert time.monotonic() - start < 10


def test_local_builds_default_to_one_thread_per_core_within_memory():
    from flexcal.validation.prototype.fem_provider import BUILD_MEMORY_BYTES, plan_local_builds

    plenty = 100 * BUILD_MEMORY_BYTES
    # the default: one thread per core, no more threads than segments, no fewer than one
    assert plan_local_builds(None, 18, cores=2, available_bytes=plenty) == (2, 1)
    assert plan_local_builds(None, 18, cores=8, available_bytes=plenty) == (8, 1)
    assert plan_local_builds(None, 3, cores=8, available_bytes=plenty) == (3, 2)  # each owns 8 // 3 cores
    assert plan_local_builds(None, 1, cores=2, available_bytes=plenty) == (1, 2)
    assert plan_local_builds(None, 0, cores=2, available_bytes=plenty) == (0, 0)
    # free memory for 3 builds on 8 cores: 3 threads; for none: still one (built in turn)
    assert plan_local_builds(None, 18, cores=8, available_bytes=3.5 * BUILD_MEMORY_BYTES) == (3, 2)
    assert plan_local_builds(None, 18, cores=8, available_bytes=0.2 * BUILD_MEMORY_BYTES) == (1, 8)
    # a heavier job (the segment derivatives, TAYLOR_MEMORY_BYTES): fewer fit in the same memory
    from flexcal.validation.prototype.tied_taylor import TAYLOR_MEMORY_BYTES

    assert plan_local_builds(None, 6, cores=2, available_bytes=3 * BUILD_MEMORY_BYTES) == (2, 1)
    assert plan_local_builds(None, 6, cores=2, available_bytes=3 * BUILD_MEMORY_BYTES,
                             job_bytes=TAYLOR_MEMORY_BYTES) == (1, 2)
    # asked for: as asked, whatever the memory; 0 is this process on all cores
    assert plan_local_builds(2, 18, cores=2, available_bytes=0.0) == (2, 1)
    assert plan_local_builds(4, 18, cores=2, available_bytes=plenty) == (4, 1)
    assert plan_local_builds(0, 18, cores=2, available_bytes=plenty) == (0, 0)
    with pytest.raises(ValueError, match="--workers=-1 must be >= 0"):
        plan_local_builds(-1, 18, cores=2, available_bytes=plenty)


def _blas_threads_seen(item, **options):
    from threadpoolctl import threadpool_info

    # OpenBLAS's pools, numpy's and scipy's (the dense products): MKL's count seen from a new thread
    # is that thread's own (PARDISO sets it per job, ``solver_threads``), not the global pool's
    return {"key": item, "threads": sorted({pool["num_threads"] for pool in threadpool_info()
                                            if pool["internal_api"] == "openblas"}), "wall_s": 0.0}


def test_threaded_builds_keep_the_dense_blas_to_each_jobs_share(tmp_path, monkeypatch):
    # two job threads on 2 cores each ran OpenBLAS on both cores for the condensations' dense
    # products: a cold table1 truth took 33.7 s where one BLAS thread each gave 26.6 s (session 30)
    import numpy as np
    from threadpoolctl import threadpool_info

    from flexcal.validation.prototype import fem_provider

    import scipy.linalg  # noqa: F401 - scipy's OpenBLAS loaded too

    np.ones((4, 4)) @ np.ones((4, 4))  # numpy's OpenBLAS loaded
    before = [pool["num_threads"] for pool in threadpool_info()]
    seen = {}
    monkeypatch.setattr("flexcal.validation.executor.usable_cores", lambda: 2)
    monkeypatch.setattr("flexcal.fem.cache.keep_cached", lambda key, arrays, directory=None: seen.update({key: arrays}))
    keys = ["a" * 64, "b" * 64]  # cache keys: SHA-256 digests
    built = fem_provider.build_missing({key: key for key in keys}, _blas_threads_seen, {}, ("threads",), str, workers=2,
                                       scheduler=None, progress=False, cache_directory=tmp_path, in_threads=True,
                                       task_prefix="t", what="test jobs")
    assert built == 2 and [seen[k]["threads"] for k in keys] == [[1], [1]]  # 2 cores // 2 job threads
    assert [pool["num_threads"] for pool in threadpool_info()] == before  # given back when the jobs end


def test_prepare_gets_exactly_the_slices_the_prototype_asks_for():
    """``build_prototype`` announces its slices before asking: the parallel build then
    covers every call (none left for the sequential path) and builds nothing unused."""
    base = analytic_provider()
    asked, announced = [], []

    def provider(chain, x_start, x_end):
        asked.append((chain, x_start, x_end))
        return base(chain, x_start, x_end)

    provider.prepare = lambda slices: announced.append(list(slices))
    mechanism = reference_mechanism()
    build_prototype(mechanism, [(0.0, 0.0, 1.0, 2.0)] * 3, provider)
    assert len(announced) == 1
    assert set(announced[0]) == set(asked) and len(announced[0]) == len(set(asked))
    assert announced[0] == chain_slices(p.chain for p in mechanism.chains)


def test_segments_are_handed_out_longest_first(tmp_path, monkeypatch):
    """The leaf segments (thinnest leaves first: most tets) go to the workers before the
    strut segments, which then fill the gaps at the end; the sort is stable. By default
    they are built on one thread per core (here 2 cores), each meshing and solving on its
    share of the cores; with --workers 0 and on a cluster given by address fTetWild and
    PARDISO keep all cores (0)."""
    import flexcal.validation.executor as executor
    from flexcal.validation.prototype.fem_provider import segment_build_cost

    submitted, plans = [], []

    def record(items, job, on_done, **kw):
        submitted.extend(items)
        options = kw["job_options"]
        plans.append((kw["workers"], kw["in_threads"], options["mesher_threads"], options["solver_threads"]))
        return {}

    monkeypatch.setattr(executor, "run_jobs", record)
    monkeypatch.setattr(executor, "usable_cores", lambda: 2)
    mechanism = reference_mechanism()
    slices = chain_slices(p.chain for p in mechanism.chains)
    build_segments(slices, cache_directory=tmp_path, progress=False)  # the default: workers None
    build_segments(slices, cache_directory=tmp_path, workers=1, progress=False)
    build_segments(slices, cache_directory=tmp_path, workers=0, progress=False)
    build_segments(slices, cache_directory=tmp_path, scheduler="tcp://127.0.0.1:1", progress=False)
    assert plans == [(2, True, 1, 1), (1, True, 2, 2), (0, False, 0, 0), (0, False, 0, 0)]
    submitted = submitted[:len(submitted) // 4]
    costs = [segment_build_cost(segment) for segment in submitted]
    assert len(submitted) == 9 and costs == sorted(costs, reverse=True)  # 9 distinct segments of the mount
    struts = [segment for segment in submitted if not any(k.startswith("leaf") for k, _, _ in segment.segments())]
    assert len(struts) == 3 and submitted[-3:] == struts and costs[-1] == 0.0
    thinnest = min(min(s.chain.thickness_1, s.chain.thickness_2) for s in submitted)
    assert min(submitted[0].chain.thickness_1, submitted[0].chain.thickness_2) == thinnest


def _small_slices():
    """The first two slices of the 150 mm driving chain (leaf 1, leaf 2): cheap at 1 element through."""
    chain = reference_mechanism().chains[3].chain
    xs = section_nodes(chain)
    return [(chain, float(xs[0]), float(xs[1])), (chain, float(xs[1]), float(xs[2]))]


@pytest.mark.slow
def test_parallel_segment_build_equals_sequential(tmp_path, monkeypatch):
    """Two segments built side by side on 2 threads of this process (the local parallel
    build since session 9) and one after the other: the same cache keys, and the same matrices up to the solver's
    round-off. The provider then serves every slice from the cache (no new
    file) and returns the stored matrix bit for bit."""
    monkeypatch.chdir(tmp_path)  # pytetwild's __tracked_surface.stl (the mesher also moves into a temp folder)
    slices = _small_slices()
    sequential, parallel = tmp_path / "sequential", tmp_path / "parallel"
    assert build_segments(slices, elements_through_thickness=1, cache_directory=sequential, workers=0,
                          progress=False) == 2
    assert build_segments(slices, elements_through_thickness=1, cache_directory=parallel, workers=2,
                          progress=False) == 2
    names = sorted(p.name for p in sequential.glob("*.npz"))
    assert names == sorted(p.name for p in parallel.glob("*.npz")) and len(names) == 2
    provider = fem_provider(elements_through_thickness=1, cache_directory=parallel, progress=False, workers=2)
    assert build_segments(slices, elements_through_thickness=1, cache_directory=parallel, workers=2) == 0
    for chain, x0, x1 in slices:
        segment, mirrored = canonical_segment(chain, x0, x1)
        assert not mirrored
        key = segment_cache_key(segment, elements_through_thickness=1)
        stored_parallel = load_cached(key, parallel)["stiffness"]
        stored_sequential = load_cached(key, sequential)["stiffness"]
        assert np.array_equal(provider(chain, x0, x1), stored_parallel)
        c_parallel = np.diag(np.linalg.inv(stored_parallel[6:, 6:]))
        c_sequential = np.diag(np.linalg.inv(stored_sequential[6:, 6:]))
        # the same mesh both ways (seeded fTetWild, surface in one order: docs/meshing.md;
        # unseeded, 10 builds spread up to 1.2 %); what differs is PARDISO's thread count,
        # 1 in a job thread, all cores here, which changes the last bits: ~1e-11 relative on
        # chain D1's compliance diagonal (fem/solve.py). 1e-9 leaves 100x for that and
        # fails on any change of mesh
        np.testing.assert_allclose(c_parallel, c_sequential, rtol=1e-9)
    assert len(list(parallel.glob("*.npz"))) == 2  # the provider's calls built nothing more


# --- a real Dask cluster on localhost ------------------------------------------------------

@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """A ``dask scheduler`` (free port: --port 0, address from its scheduler file) and two
    single-threaded ``dask worker`` processes, whose FEM cache is their own folder (not the
    test's: results must come back through the executor). Torn down at the end."""
    folder = tmp_path_factory.mktemp("dask")
    scheduler_file = folder / "scheduler.json"
    env = {**os.environ, "FLEXCAL_CACHE_DIR": str(folder / "worker-cache")}
    processes = [subprocess.Popen([*SCHEDULER, "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                   "--scheduler-file", str(scheduler_file)], cwd=folder, env=env,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60  # scheduler start-up: a few seconds, slower under load
        while not scheduler_file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert scheduler_file.exists(), "dask scheduler did not start within 60 s"
        address = json.loads(scheduler_file.read_text())["address"]
        for name in ("w1", "w2"):
            processes.append(subprocess.Popen([*WORKER, address, "--nthreads", "1", "--nworkers", "1",
                                               "--no-dashboard", "--name", name, "--local-directory",
                                               str(folder / name)], cwd=folder, env=env,
                                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from dask.distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
        yield {"address": address, "worker_cache": folder / "worker-cache"}
    finally:
        for process in reversed(processes):
            process.terminate()
        for process in processes:
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


def _task_prefixes(address: str) -> set[str]:
    from dask.distributed import Client

    with Client(address, timeout=30) as client:
        return set(client.run_on_scheduler(lambda dask_scheduler: list(dask_scheduler.task_prefixes)))


def _seed_cache_except(mechanism, cache: Path, keep) -> tuple:
    """Store the closed-form stiffness under the FEM key of every slice of ``mechanism``
    except the one ``keep`` picks, so that a job on it has exactly one real FEM segment to
    build (the closed form stands in for segments that are not under test here). Returns
    the kept (segment, key)."""
    analytic = analytic_provider()
    kept = None
    for chain, x0, x1 in chain_slices(p.chain for p in mechanism.chains):
        segment, _ = canonical_segment(chain, x0, x1)
        key = segment_cache_key(segment, elements_through_thickness=DEFAULT_ELEMENTS_THROUGH)
        if keep(segment) and kept is None:
            kept = (segment, key)
        elif kept is None or key != kept[1]:
            store_cached(key, {"stiffness": analytic(chain, segment.x_start, segment.x_end)}, cache)
    assert kept is not None
    return kept


def _is_strut(segment) -> bool:
    """The strut piece of a driving chain: no leaf, the cheapest segment to mesh."""
    return segment.chain.length < 0.2 and all(k in ("strut",) for k, _, _ in segment.segments())


@pytest.mark.slow
def test_truth_builds_its_missing_segment_on_the_cluster(dask_cluster, tmp_path, monkeypatch):
    """``flexcal truth --provider fem-rigid --scheduler ADDRESS``: the one missing FEM segment is
    built on the cluster and handed back into this machine's cache (the workers have their own).
    The rigid cuts' provider reads segments; the default one reads tied chains since session 25
    (the next test), and this test, which named no provider, failed from then on."""
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import as_built

    cache = tmp_path / "cache"
    monkeypatch.setenv("FLEXCAL_CACHE_DIR", str(cache))
    monkeypatch.chdir(tmp_path)
    scenario = load_scenario("table1")
    mechanism, _, _ = as_built(scenario.space, scenario.values)
    segment, key = _seed_cache_except(mechanism, cache, _is_strut)
    assert load_cached(key, cache) is None
    out = tmp_path / "truth"
    assert cli.main(["truth", "--scenario", "table1", "--provider", "fem-rigid", "--scheduler", dask_cluster["address"],
                     "--out", str(out), "-q"]) == 0
    assert load_cached(key, cache) is not None  # handed back by the executor
    assert load_cached(key, dask_cluster["worker_cache"]) is not None  # built there
    assert "fem-segment" in _task_prefixes(dask_cluster["address"])
    assert (out / "curves.csv").exists()


@pytest.mark.slow
def test_truth_builds_its_tied_chains_on_the_cluster(dask_cluster, tmp_path, monkeypatch):
    """``flexcal truth --scheduler ADDRESS`` with the default prototype: its six tied chains are
    built on the cluster and handed back into this machine's cache (the workers have their own)."""
    cache = tmp_path / "cache"
    monkeypatch.setenv("FLEXCAL_CACHE_DIR", str(cache))
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "truth"
    assert cli.main(["truth", "--scenario", "table1", "--scheduler", dask_cluster["address"], "--out", str(out),
                     "-q"]) == 0
    entries = {path.name for path in cache.iterdir()}  # handed back by the executor: the six chains' entries
    assert len(entries) == 6 and all(name.endswith(".npz") for name in entries), entries
    assert entries <= {path.name for path in dask_cluster["worker_cache"].iterdir()}  # built there
    assert "fem-tied-chain" in _task_prefixes(dask_cluster["address"])
    assert (out / "curves.csv").exists()


@pytest.mark.slow
def test_compensate_bench_builds_on_the_cluster(dask_cluster, tmp_path, monkeypatch):
    """``compensate``'s bench (the prototype rebuilt from a FEM sidecar) builds its missing
    segment through ``--scheduler``; the bench drives themselves stay sequential."""
    from flexcal.validation.runs.compensate import bench_from_metadata
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import as_built, make_truth

    cache = tmp_path / "cache"
    monkeypatch.setenv("FLEXCAL_CACHE_DIR", str(cache))
    monkeypatch.chdir(tmp_path)
    scenario = load_scenario("table1", seed=3)
    metadata = dict(make_truth(scenario, analytic_provider()).measurement.metadata)
    metadata["provider"] = fem_provider().description  # a FEM prototype's sidecar
    mechanism, _, _ = as_built(scenario.space, scenario.values)
    segment, key = _seed_cache_except(mechanism, cache, _is_strut)
    bench = bench_from_metadata(metadata, scenario.space, scheduler=dask_cluster["address"])
    assert bench is not None and bench.prototype.provider_description.startswith("FEM")
    assert load_cached(key, cache) is not None
    assert load_cached(key, dask_cluster["worker_cache"]) is not None


@pytest.mark.slow
def test_diagnose_benchmark_cases_on_the_cluster_equal_in_process(dask_cluster, tmp_path):
    """One tiny-grid case (analytic prototype) through ``--scheduler`` and in this process
    (``--workers 0``): the same row, bit for bit apart from its wall time."""
    rows = {}
    for name, options in (("cluster", ["--scheduler", dask_cluster["address"]]), ("here", ["--workers", "0"])):
        out = tmp_path / name
        assert cli.main(["diagnose-benchmark", "--grid", "tiny", "--effects", "drift", "--out", str(out), "-q",
                         *options]) == 0
        report = json.loads((out / "report.json").read_text())
        assert report["failures"] == {} and len(report["rows"]) == 1
        rows[name] = {k: v for k, v in report["rows"][0].items() if k != "wall_s"}
        assert len(list((out / "cases").glob("*.json"))) == 1  # the resumable store
    assert rows["cluster"] == rows["here"]
    assert "case" in _task_prefixes(dask_cluster["address"])
