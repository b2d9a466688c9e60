"""``flexcal sweep``: FEM vs closed form over a grid or Latin hypercube of hinge or chain
dimensions, on local worker processes or a Dask distributed cluster.

Per design: FEM and closed-form 6 x 6 compliances and their diagonal discrepancy, peak
stress per unit rotation, optionally identification accuracy on the table1 scenario.
Writes DIR/designs/<id>.json as each design finishes (an interrupted sweep resumes where
it stopped when run again with the same DIR), then DIR/sweep.csv, DIR/report.json,
DIR/discrepancy.png and DIR/stress.png. Config keys: ``flexcal sweep --print-config``;
format: docs/sweep.md.
"""

from __future__ import annotations

import argparse

from ..sweep.space import DEFAULT_CONFIG

__all__ = ["configure", "run", "EXAMPLES", "DEFAULT_CONFIG"]

# --out holds the finished designs of an earlier run, which a rerun resumes (no --force)
RESUMES_OUT = True

EXAMPLES = (
    "flexcal sweep --config examples/sweep_notch.toml --out runs/sweep",
    "flexcal sweep --config examples/sweep_notch.toml --out runs/sweep --workers 0     # in this process",
    "flexcal sweep --config examples/sweep_notch.toml --out runs/sweep --scheduler tcp://10.0.0.5:8786",
    "flexcal sweep --print-config > my_sweep.toml",
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", metavar="DIR", required=True,
                        help="output folder (designs/<id>.json as they finish, then sweep.csv, report.json, PNGs); "
                             "run again with the same DIR to resume")
    from .options import scheduler_address, worker_count

    parser.add_argument("--scheduler", type=scheduler_address, metavar="ADDRESS", default=None,
                        help="address of a Dask scheduler (tcp://host:8786); default: a local cluster")
    parser.add_argument("--workers", type=worker_count, metavar="N", default=None,
                        help="local worker processes (default: min(cores, designs); 0: run in this process)")
    parser.add_argument("--seed", type=int, metavar="N", default=None,
                        help="seed of the Latin-hypercube sample (overrides [sweep] seed)")
    parser.add_argument("--cache-dir", metavar="DIR", default=None,
                        help="FEM cache folder (default $FLEXCAL_CACHE_DIR or ~/.cache/flexcal)")
    from .options import add_mount

    add_mount(parser, what="the reference mount in the identification column ([identification] enabled = true)")
    # --config FILE and --print-config come from cli.py (this module has DEFAULT_CONFIG)


def _config(args: argparse.Namespace) -> dict:
    config = getattr(args, "config", None)
    if isinstance(config, dict) and config:
        return config  # merged by cli.py: defaults < file
    path = getattr(args, "config_path", None)
    if path is None:
        return dict(DEFAULT_CONFIG)
    from ..config import read_config_file

    return read_config_file(path, DEFAULT_CONFIG)


def run(args: argparse.Namespace) -> int:
    from ..sweep.run import run_sweep

    if args.workers is not None and args.workers < 0:
        raise ValueError(f"--workers={args.workers} must be >= 0 (0: run in this process)")
    from .options import mount_option

    mount = mount_option(args)
    if mount is not None:
        from flexcal.geometry.mount import mount_table

        mount = mount_table(mount)  # the content, not the path, goes into each design (and its id)
    result = run_sweep(_config(args), args.out, workers=args.workers, scheduler=args.scheduler, seed=args.seed,
                       cache_directory=args.cache_dir, progress=not getattr(args, "quiet", False), mount=mount)
    n_done = sum(r is not None for r in result.records)
    print(f"flexcal sweep: {n_done}/{len(result.records)} designs finished ({len(result.computed)} computed now), "
          f"{result.wall_s:.1f} s; wrote {args.out}/sweep.csv, report.json, discrepancy.png, stress.png")
    if result.failures:
        print(f"flexcal sweep: {len(result.failures)} design(s) failed (see {args.out}/report.json); "
              f"run again to retry them")
        return 1
    return 0
