"""Cold ``flexcal truth --scenario table1``: sequential FEM segment builds against local
worker processes, side by side in one run (issue #14, docs/scale.md).

Each run is the command line as a user types it, in a subprocess with its own empty
``FLEXCAL_CACHE_DIR`` (so every FEM segment is built) and its own ``--out``; the modes
alternate (sequential, parallel, sequential, ...) so a change of the machine's load
hits both alike. Prints each wall time, the medians and the ratio parallel / sequential
(goal <= 0.6 with 2 workers), the CPU seconds of each run (command + its worker
processes: how many cores it kept busy) and the load average. Not a test.

A third mode (``--bound``, Linux) runs the sequential command held to one core
(``sched_setaffinity``): its wall time W1 is the job's work on one core, every thread
of fTetWild and MKL sharing it. N workers that added no overhead of their own and
never idled would take W1 / N, so (W1 / N) / sequential is the yardstick for the
parallel ratio (not a hard floor: work done on two cores at once can cost more or less
CPU than on one).

    .venv/bin/python benchmarks/bench_scale.py                  # 1 repeat, 2 workers
    .venv/bin/python benchmarks/bench_scale.py --repeats 3 --workers 2 --bound
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FLEXCAL = str(Path(sys.executable).with_name("flexcal"))


def timed_truth(workers: int, root: Path, label: str, cores: set[int] | None = None) -> float:
    """Wall time [s] of one cold table1 truth with ``--workers workers`` (on the CPU
    ``cores`` only, if given)."""
    cache, out = root / f"cache-{label}", root / f"out-{label}"
    cache.mkdir()
    env = {**os.environ, "FLEXCAL_CACHE_DIR": str(cache)}
    command = [FLEXCAL, "truth", "--scenario", "table1", "--out", str(out), "--workers", str(workers), "-q"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    pin = (lambda: os.sched_setaffinity(0, cores)) if cores else None
    subprocess.run(command, env=env, cwd=root, check=True, preexec_fn=pin)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    # CPU of the command and its reaped children (meshing children, worker processes)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    n_entries = len(list(cache.glob("*.npz")))
    print(f"{label:>14}: {wall:7.1f} s wall, {cpu:7.1f} s CPU (cores busy on average {cpu / wall:.2f}); "
          f"{n_entries} FEM cache entries built; load average now {os.getloadavg()[0]:.2f}", flush=True)
    shutil.rmtree(cache)
    shutil.rmtree(out)
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=1, help="runs of each mode (default 1)")
    parser.add_argument("--workers", type=int, default=2, help="local workers of the parallel mode (2)")
    parser.add_argument("--bound", action="store_true",
                        help="also the sequential run on one core: the yardstick W1 / workers / sequential")
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())}; {os.cpu_count()} cores", flush=True)
    sequential, parallel, one_core = [], [], []
    with tempfile.TemporaryDirectory(prefix="flexcal-bench-scale-") as folder:
        root = Path(folder)
        for r in range(args.repeats):
            sequential.append(timed_truth(0, root, f"sequential-{r}"))
            parallel.append(timed_truth(args.workers, root, f"workers{args.workers}-{r}"))
            if args.bound:
                one_core.append(timed_truth(0, root, f"one-core-{r}", cores={min(os.sched_getaffinity(0))}))
    seq, par = statistics.median(sequential), statistics.median(parallel)
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    print(f"median sequential {seq:.1f} s, median {args.workers} workers {par:.1f} s, "
          f"ratio parallel / sequential {par / seq:.2f} (goal <= 0.60)")
    if one_core:
        w1 = statistics.median(one_core)
        print(f"median on one core W1 {w1:.1f} s: {args.workers} workers without overhead or idling would take "
              f"W1 / {args.workers} = {w1 / args.workers:.1f} s, ratio {w1 / args.workers / seq:.2f} (the "
              f"yardstick); the parallel run took {par / (w1 / args.workers):.2f} x that")


if __name__ == "__main__":
    main()
