"""One executor for the heavy jobs: independent items run in this process, on a Dask
``LocalCluster`` of worker processes, or on an existing Dask distributed cluster.

``run_jobs(items, job, on_done, key=...)`` runs ``job(item, **job_options)`` for every
item and calls ``on_done(item, result)`` in the calling process as each one finishes
(``as_completed``), so the caller can store it at once (sweep designs, benchmark cases,
FEM cache entries); an item that raises is returned in the failures, never sinks the
others.

- ``workers=0``: one after the other in this process (debugging, tiny jobs);
- ``workers=N``: a ``LocalCluster`` of N single-threaded worker processes, or, with
  ``in_threads=True``, N threads of this process: for jobs whose heavy work runs outside
  the interpreter lock (the FEM segment builds: fTetWild meshes in a child process,
  PARDISO and numpy release the lock), where N processes would each import the whole
  FEM stack again and run Dask beside it (docs/scale.md, "Session 9");
- ``scheduler="tcp://host:8786"``: an existing cluster (``workers`` is then ignored).
  Workers need flexcal installed; for a shared FEM cache, the same cache folder
  (``$FLEXCAL_CACHE_DIR`` on shared storage).

Used by ``flexcal sweep`` (designs), the virtual prototype's FEM segment builds
(``truth``, ``verify``, ``compensate``, ``diagnose-benchmark --provider fem``) and
``diagnose-benchmark`` (cases); docs/scale.md.
"""

from __future__ import annotations

import contextlib
import logging
import os
from typing import Any, Callable, Hashable, Sequence

__all__ = ["run_jobs", "resolve_workers", "usable_cores", "where", "JobFailures"]

JobFailures = dict  # {item key: "ErrorType: message"}

# Dask settings for the LocalCluster's worker processes (not for a cluster given by address):
# - MALLOC_TRIM_THRESHOLD_ unset: Dask sets it (64 kB) so that freed memory goes back to the
#   system at once, and glibc then stops adapting its mmap threshold: every array above
#   128 kB is a fresh mmap. A FEM segment build took 3x the page faults (0.72 M against
#   0.24 M for two leaf segments) and 2-4 % more CPU (docs/scale.md). The workers keep more
#   freed memory for reuse instead;
# - the worker's statistical profiler off (a stack sample every 10 ms that nobody reads here;
#   its cost was not measured separately).
LOCAL_WORKER_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                       "distributed.worker.profile.enabled": False}


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one: a
    container or ``taskset`` may allow fewer than the machine has)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def resolve_workers(workers: int | None, n_items: int, *, cores: int | None = None) -> int:
    """Local workers to start: ``workers`` as given (0: this process), or by default
    min(cores, items to compute) (at least 1 when there is an item); cores: default
    ``usable_cores()``."""
    if workers is None:
        return max(1, min(cores or usable_cores(), n_items)) if n_items else 0
    if workers < 0:
        raise ValueError(f"--workers={workers} must be >= 0 (0: run in this process)")
    return int(workers)


def where(workers: int, scheduler: str | None, in_threads: bool = False) -> str:
    """Where the items run, in words (for progress lines)."""
    if scheduler is not None:
        return f"the Dask cluster at {scheduler}"
    if not workers:
        return "this process"
    if in_threads:
        return "1 thread of this process" if workers == 1 else f"{workers} threads of this process"
    return f"{workers} local worker process(es)"


def _stop_the_jobs_children(cluster) -> None:
    """Kill the processes that the jobs on a LocalCluster's workers started (fTetWild's
    meshing children): the jobs are abandoned (Ctrl-C, SIGTERM, an error), and a worker
    blocked waiting for its child cannot stop until the child ends; Dask's nanny then
    waits 4 s before it kills the worker. With the child gone, the job fails at once and
    the worker stops."""
    import psutil

    for nanny in list(cluster.workers.values()):
        try:
            _kill(psutil.Process(nanny.pid).children(recursive=True))
        except (psutil.Error, TypeError, ValueError):  # gone already, or not started (pid None)
            continue


def _kill_new_children(before: set[int]) -> None:
    """Kill this process's child processes (and theirs) but those in ``before`` (pids)."""
    import psutil

    _kill([child for child in psutil.Process().children(recursive=True) if child.pid not in before])


def _kill(processes) -> None:
    """SIGKILL each of ``processes`` (psutil.Process) that is still there."""
    import psutil

    for process in processes:
        with contextlib.suppress(psutil.Error):
            process.kill()


# How often an abandoned threaded run looks for new child processes of its running jobs
# (killing them) until those jobs end: a child lives at most this long (plus its kill).
ABANDON_POLL_S = 0.05


def _run_in_threads(items: Sequence[Any], job: Callable[..., Any], on_done: Callable[[Any, Any], None],
                    key: Callable[[Any], Hashable], workers: int, job_options: dict[str, Any]) -> JobFailures:
    """``run_jobs`` on ``workers`` threads of this process. On an interrupt the jobs not
    started are dropped and the child processes the running ones start are killed until
    those jobs end, so they fail at once instead of finishing their mesh (a thread cannot
    be stopped from outside: one that was in Python or in PARDISO when the interrupt came
    goes on to its next child process, which is killed in turn; ``ABANDON_POLL_S``)."""
    from concurrent.futures import ThreadPoolExecutor, as_completed, wait

    import psutil

    failures: JobFailures = {}
    before = {child.pid for child in psutil.Process().children(recursive=True)}
    pool = ThreadPoolExecutor(workers, thread_name_prefix="flexcal-job")
    futures: dict = {}
    try:
        futures = {pool.submit(job, item, **job_options): item for item in items}
        for future in as_completed(futures):
            item = futures[future]
            try:
                result = future.result()
            except Exception as error:  # one bad item must not sink the others
                failures[key(item)] = f"{type(error).__name__}: {error}"
                continue
            on_done(item, result)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        running = [future for future in futures if not future.done()]
        while running:
            _kill_new_children(before)
            running = list(wait(running, timeout=ABANDON_POLL_S).not_done)
        raise
    pool.shutdown()
    return failures


def run_jobs(items: Sequence[Any], job: Callable[..., Any], on_done: Callable[[Any, Any], None], *,
             key: Callable[[Any], Hashable], workers: int, scheduler: str | None = None,
             job_options: dict[str, Any] | None = None, task_prefix: str = "item",
             in_threads: bool = False) -> JobFailures:
    """Run ``job(item, **job_options)`` for every item; ``on_done(item, result)`` as each
    finishes (in this process); returns {key(item): error text} of the items that raised.

    key: a unique, stable name of an item (also the Dask task key); workers: 0 runs in
    this process, N > 0 on a LocalCluster of N processes (ignored with ``scheduler``), or
    on N threads of this process with ``in_threads`` (module doc).
    KeyboardInterrupt propagates after the cluster is shut down; finished items have
    already been handed to ``on_done``.
    """
    job_options = dict(job_options or {})
    failures: JobFailures = {}
    if not items:
        return failures
    if scheduler is None and workers > 0 and in_threads:
        return _run_in_threads(items, job, on_done, key, workers, job_options)
    if scheduler is None and workers == 0:
        for item in items:
            try:
                result = job(item, **job_options)
            except Exception as error:  # one bad item must not sink the others
                failures[key(item)] = f"{type(error).__name__}: {error}"
                continue
            on_done(item, result)
        return failures
    from dask.distributed import Client, LocalCluster, as_completed

    # Dask's own log lines only with -v, apart from errors: its warnings are about its
    # internals (a stop with tasks running: "... ended with CancelledError", "Worker process
    # still alive after 4.0 seconds, killing"), and flexcal reports failed items itself
    quiet = logging.getLogger().getEffectiveLevel() > logging.INFO
    previous_level = logging.getLogger("distributed").level
    if quiet:
        logging.getLogger("distributed").setLevel(logging.ERROR)
    cluster = None
    try:
        if scheduler is not None:
            client = Client(scheduler)
        else:
            import dask

            # no fixed dashboard port: other jobs may run on the same machine
            with dask.config.set(LOCAL_WORKER_CONFIG):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=logging.ERROR if quiet else logging.INFO)
            client = Client(cluster)
        try:
            futures = {client.submit(job, item, **job_options, key=f"{task_prefix}-{key(item)}", pure=False): item
                       for item in items}
            for future in as_completed(futures):
                item = futures[future]
                try:
                    result = future.result()
                except Exception as error:
                    failures[key(item)] = f"{type(error).__name__}: {error}"
                    continue
                on_done(item, result)
        finally:
            client.close()
    except BaseException:
        if cluster is not None:
            _stop_the_jobs_children(cluster)
        raise
    finally:
        if cluster is not None:
            cluster.close()
        logging.getLogger("distributed").setLevel(previous_level)
    return failures
