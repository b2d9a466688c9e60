"""``flexcal report``: one self-contained HTML page from a run folder.

Reads DIR/report.md, DIR/report.json and the PNGs of DIR (any flexcal command's
``--out`` folder) and writes DIR/report.html (or ``--html FILE``): the markdown report,
the pictures embedded, every report.json figure as a table, links to the other files.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

__all__ = ["configure", "run", "EXAMPLES", "write_html_report"]

EXAMPLES = (
    "flexcal report runs/table1                  # -> runs/table1/report.html",
    "flexcal report runs/hinge --html hinge.html",
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", metavar="DIR", help="a run folder (the --out of another flexcal command)")
    parser.add_argument("--html", metavar="FILE", help="where to write the page (default DIR/report.html)")


def write_html_report(folder: str | os.PathLike, target: str | os.PathLike | None = None) -> Path:
    """Render ``folder`` and write the page whole or not at all; returns its path."""
    from ..output import write_text
    from ..reports.html import render_run_folder

    page = render_run_folder(folder)
    target = Path(target) if target is not None else Path(folder) / "report.html"
    if target.is_dir():
        raise ValueError(f"--html {target} is a folder; give a file name")
    target.parent.mkdir(parents=True, exist_ok=True)
    write_text(target, page)
    return target


def run(args: argparse.Namespace) -> int:
    """The page of a folder no run is writing: the folder's ``--out`` lock is taken while
    it is read and the page written (``out_lock.reserved``), so a running command's folder
    is refused (one line, exit 2) instead of rendered half-written, and no command can
    start writing it meanwhile. A folder this user cannot write (someone else's run,
    read-only media) is read without the lock: no run of this user can be writing it."""
    import contextlib

    from ..out_lock import OutInUse, reserved

    with contextlib.ExitStack() as stack:
        if Path(args.folder).is_dir():
            try:
                stack.enter_context(reserved(args.folder, command="report"))
            except OutInUse:
                raise
            except OSError:
                pass
        target = write_html_report(args.folder, args.html)
    print(f"flexcal report: wrote {target} ({target.stat().st_size / 1e3:.0f} kB, self-contained)")
    return 0
