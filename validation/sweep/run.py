"""Hinge-dimension sweeps: designs -> workers -> a resumable store -> table and plots.

``run_sweep(config, out)`` evaluates every design of the config
(``sweep.space.designs_from_config``) with ``sweep.job.evaluate_design``:

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
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from ..executor import resolve_workers, run_jobs, where as executor_where
from ..output import out_folder, write_json
from .space import design_id, designs_from_config

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
    as each finishes; returns {design id: error text} of the designs that raised
    (``executor.run_jobs``, the executor every heavy job shares)."""
    return run_jobs(designs, job, lambda _design, record: on_done(record), key=design_id, workers=workers,
                    scheduler=scheduler, job_options=job_options, task_prefix="design")


def run_sweep(config: dict[str, Any], out: str | os.PathLike, *, workers: int | None = None,
              scheduler: str | None = None, seed: int | None = None, cache_directory: str | None = None,
              progress: bool = True, job: Callable[..., dict[str, Any]] | None = None,
              mount: dict[str, Any] | None = None) -> SweepResult:
    """Evaluate the config's designs not yet in OUT/designs, then write the table and plots.

    workers: LocalCluster size (default: min(cores, designs to compute); 0 runs in this
    process); scheduler: address of a Dask scheduler (then ``workers`` is ignored);
    seed: overrides [sweep] seed; cache_directory: FEM cache (default ``~/.cache/flexcal``);
    mount: a mount file's table (``flexcal.geometry.mount.mount_table``) the identification
    column runs on instead of the reference mount (``--mount FILE``).
    """
    from .job import evaluate_design
    from .table import write_tables

    start = time.perf_counter()
    log = (lambda text: print(text, file=sys.stderr)) if progress else (lambda text: None)
    designs = designs_from_config(config, seed=seed, mount=mount)
    out = out_folder(out, resume=True)  # finished designs of an earlier run are kept and reused
    store = DesignStore(out / "designs")
    ids = [design_id(d) for d in designs]
    unique = dict(zip(ids, designs))  # a value listed twice is one design
    pending = [d for i, d in unique.items() if store.load(i) is None]
    workers = resolve_workers(workers, len(pending))
    where = executor_where(workers, scheduler)
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
