"""``flexcal mount``: print an example mount file, or check one, summarize it and see it.

    flexcal mount --example > my.mount.toml     # the reference mount, every key commented
    flexcal mount my.mount.toml                 # read + check + summary (a few seconds)
    flexcal mount my.mount.toml --out runs/see  # also mount.png, mount.step, report.json

A mount file (docs/mount.md) describes the whole mount in display units; every command that
models a mount takes it as ``--mount FILE``. The checks here are the ones ``--mount`` runs
before any computation: impossible dimensions, bodies whose solids overlap, a direction the
chains' axes do not hold, a workspace the stroke cannot reach (each one line, exit 2), and a
warning when the load chains' axes miss one remote centre. The summary
(``flexcal.validation.mount_summary``) adds each chain's axial load under the payload at zero
inputs and which drives pass through their clearance over the standard trajectory (closed-form
segments: no FEM). ``--out`` draws the mount (``reports.mount_view``) and writes its STEP.
"""

from __future__ import annotations

import argparse

from .options import add_out

__all__ = ["configure", "run", "EXAMPLES"]

EXAMPLES = (
    "flexcal mount --example > my.mount.toml",
    "flexcal mount my.mount.toml",
    "flexcal mount my.mount.toml --out runs/my-mount   # mount.png, mount.step, report.json",
    "flexcal truth --scenario table1 --mount my.mount.toml --out runs/mine",
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE", nargs="?", help="a mount file to check and summarize")
    parser.add_argument("--example", action="store_true",
                        help="print the reference mount's file (DESIGN.md), every key commented")
    add_out(parser, required=False, what="mount.png: the mount drawn with its chains named; mount.step: its solids "
                                         "in mm; report.json: the summary")


def run(args: argparse.Namespace) -> int:
    from flexcal.geometry.mount import mount_text
    from flexcal.geometry.params import reference_mechanism

    from ..mount_checks import read_checked_mount
    from ..mount_summary import mount_summary, summary_lines, summary_report

    if args.example == (args.file is not None):
        raise ValueError("give a mount FILE to check, or --example (not both)")
    if args.example:
        if args.out:
            raise ValueError("--out draws a mount FILE; with --example, write the file first: "
                             "flexcal mount --example > my.mount.toml")
        print(mount_text(reference_mechanism(), name="reference"), end="")
        return 0
    mechanism = read_checked_mount(args.file)
    summary = mount_summary(mechanism)
    print(f"flexcal mount: {args.file} is a valid mount; payload {mechanism.payload_mass:g} kg")
    print("\n".join(summary_lines(summary)))
    if args.out:
        from ..output import staged_output, write_report
        from ..reports.mount_view import write_mount_picture, write_mount_step

        with staged_output(args.out, replace=args.force) as staging:
            write_mount_picture(mechanism, staging / "mount.png", title=str(args.file))
            write_mount_step(mechanism, staging / "mount.step")
            write_report(staging, summary_report(summary, source=str(args.file)))
        print(f"  wrote {args.out}/mount.png, mount.step, report.json")
    return 0
