"""Hinge-dimension sweeps: designs -> workers -> a resumable store -> table and plots.

``run_sweep(config, out)`` evaluates every design of the config
(``sweep_space.designs_from_config``) with ``sweep_job.evaluate_design``:

- ``workers=0``: one after the other in this process (debugging, tiny sweeps);
- default: a Dask ``LocalCluster`` of ``workers`` single-threaded worker processes;
- ``scheduler="tcp://host:8786"``: an existing Dask distributed cluster.

Results are collected with ``as_completed``; each finished design is written at once as
OUT/designs/<id>.json (atomic, fsync'ed), where <id> hashes the design. A design whose
file exists is not computed again, so an interrupted sweep (Ctrl-C, a lost worker, a
reboot) resumes where it stopped. At the end OUT/sweep.csv (one row per design of this
config), OUT/report.json and the plots are (re)written from the store.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from .output import out_folder, write_json
from .sweep_space import design_id, designs_from_config

__all__ = ["DesignStore", "SweepResult", "run_sweep", "execute"]


@dataclass(frozen=True)
class DesignStore:
    """Finished designs, one JSON file each: ``folder/<design id>.json``."""

    folder: Path

    def path(self, identifier: str) -> Path:
        return self.folder / f"{identifier}.json"

    def load(self, identifier: str) -> dict[str, Any] | None:
        """The record, or None when missing or unreadable (then it is recomputed)."""
        try:
            record = json.loads(self.path(identifier).read_text())
        except (FileNotFoundError, json.JSONDecodeError, UnicodeDecodeError):
            return None
        return record if isinstance(record, dict) and record.get("id") == identifier else None

    def save(self, record: dict[str, Any]) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        write_json(self.path(record["id"]), record, fsync=True)


@dataclass(frozen=True, kw_only=True)
class SweepResult:
    """ids and records: one per design of the config, in config order (record None:
    failed); computed: ids computed in this run; failures: {id: error text}; wall_s [s]."""

    ids: tuple[str, ...]
    records: list[dict[str, Any] | None]
    computed: tuple[str, ...]
    failures: dict[str, str]
    wall_s: float


def execute(designs: list[dict[str, Any]], job: Callable[..., dict[str, Any]], on_done: Callable, *,
            workers: int, scheduler: str | None, job_options: dict[str, Any]) -> dict[str, str]:
    """Run ``job(design, **job_options)`` for every design, calling ``on_done(record)``
    as each finishes; returns {design id: error text} of the designs that raised."""
    failures: dict[str, str] = {}
    if not designs:
        return failures
    if scheduler is None and workers == 0:
        for design in designs:
            try:
                on_done(job(design, **job_options))
            except Exception as error:  # one bad design must not sink the sweep
                failures[design_id(design)] = f"{type(error).__name__}: {error}"
        return failures
    from dask.distributed import Client, LocalCluster, as_completed

    quiet = logging.getLogger().getEffectiveLevel() > logging.INFO  # Dask's INFO lines only with -v
    previous_level = logging.getLogger("distributed").level
    if quiet:
        logging.getLogger("distributed").setLevel(logging.WARNING)
    if scheduler is not None:
        client, cluster = Client(scheduler), None
    else:
        # no fixed dashboard port: other sweeps may run on the same machine
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.WARNING if quiet else logging.INFO)
        client = Client(cluster)
    try:
        futures = {client.submit(job, design, **job_options, key=f"design-{design_id(design)}", pure=False):
                   design_id(design) for design in designs}
        for future in as_completed(futures):
            try:
                record = future.result()
            except Exception as error:
                failures[futures[future]] = f"{type(error).__name__}: {error}"
                continue
            on_done(record)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
        logging.getLogger("distributed").setLevel(previous_level)
    return failures


def run_sweep(config: dict[str, Any], out: str | os.PathLike, *, workers: int | None = None,
              scheduler: str | None = None, seed: int | None = None, cache_directory: str | None = None,
              progress: bool = True, job: Callable[..., dict[str, Any]] | None = None) -> SweepResult:
    """Evaluate the config's designs not yet in OUT/designs, then write the table and plots.

    workers: LocalCluster size (default: min(cores, designs to compute); 0 runs in this
    process); scheduler: address of a Dask scheduler (then ``workers`` is ignored);
    seed: overrides [sweep] seed; cache_directory: FEM cache (default ``~/.cache/flexcal``).
    """
    from .sweep_job import evaluate_design
    from .sweep_table import write_tables

    start = time.perf_counter()
    log = (lambda text: print(text, file=sys.stderr)) if progress else (lambda text: None)
    designs = designs_from_config(config, seed=seed)
    out = out_folder(out, resume=True)  # finished designs of an earlier run are kept and reused
    store = DesignStore(out / "designs")
    ids = [design_id(d) for d in designs]
    unique = dict(zip(ids, designs))  # a value listed twice is one design
    pending = [d for i, d in unique.items() if store.load(i) is None]
    if workers is None:
        workers = max(1, min(os.cpu_count() or 1, len(pending)))
    if workers < 0:
        raise ValueError(f"--workers={workers} must be >= 0 (0: run in this process)")
    where = scheduler or (f"{workers} local worker process(es)" if workers else "this process")
    log(f"sweep: {len(unique)} designs, {len(unique) - len(pending)} already done, {len(pending)} to compute "
        f"on {where}")
    computed: list[str] = []

    def on_done(record: dict[str, Any]) -> None:
        store.save(record)
        computed.append(record["id"])
        log(f"sweep: design {record['id']} done in {record['wall_s']:.1f} s ({len(computed)}/{len(pending)})")

    job_options = {"cache_directory": None if cache_directory is None else str(cache_directory)}
    try:
        failures = execute(pending, job or evaluate_design, on_done, workers=workers, scheduler=scheduler,
                           job_options=job_options)
    except KeyboardInterrupt:
        log(f"sweep: interrupted; {len(computed)} design(s) finished in this run are kept in {store.folder}, "
            f"run the same command again to resume")
        raise
    for identifier, text in failures.items():
        log(f"sweep: design {identifier} failed: {text}")
    records = [store.load(i) for i in ids]
    result = SweepResult(ids=tuple(ids), records=records, computed=tuple(computed), failures=failures,
                         wall_s=time.perf_counter() - start)
    write_tables(result, config, out)
    return result
