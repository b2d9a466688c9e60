"""``flexcal mount``: print an example mount file, or check one and summarize it.

    flexcal mount --example > my.mount.toml     # the reference mount, every key commented
    flexcal mount my.mount.toml                 # read + check; remote centre, chain lengths, stroke

A mount file (docs/mount.md) describes the whole mount in display units; every command that
models a mount takes it as ``--mount FILE``. The checks here are the ones ``--mount`` runs
before any computation: impossible dimensions, chains that collide, a direction the chains'
axes do not hold, a workspace the stroke cannot reach (each one line, exit 2), and a warning
when the load chains' axes miss one remote centre.
"""

from __future__ import annotations

import argparse

__all__ = ["configure", "run", "EXAMPLES"]

EXAMPLES = (
    "flexcal mount --example > my.mount.toml",
    "flexcal mount my.mount.toml",
    "flexcal truth --scenario table1 --mount my.mount.toml --out runs/mine",
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE", nargs="?", help="a mount file to check and summarize")
    parser.add_argument("--example", action="store_true",
                        help="print the reference mount's file (DESIGN.md), every key commented")


def run(args: argparse.Namespace) -> int:
    from flexcal.geometry.mount import mount_text
    from flexcal.geometry.params import reference_mechanism

    from ..mount_checks import free_twist, read_checked_mount, remote_centre, required_travel

    if args.example == (args.file is not None):
        raise ValueError("give a mount FILE to check, or --example (not both)")
    if args.example:
        print(mount_text(reference_mechanism(), name="reference"), end="")
        return 0
    mechanism = read_checked_mount(args.file)
    centre, miss = remote_centre(mechanism)
    ratio, _ = free_twist(mechanism)
    travel = required_travel(mechanism)
    print(f"flexcal mount: {args.file} is a valid mount; payload {mechanism.payload_mass:g} kg")
    print(f"  remote centre of L1-L3: ({', '.join(f'{v * 1e3:.3f}' for v in centre)}) mm, axes within "
          f"{miss * 1e3:.3g} mm of it")
    print("  chain lengths [mm]: " + ", ".join(f"{c.name} {c.chain.length * 1e3:.1f}" for c in mechanism.chains))
    placed = mechanism.payload_box_centre
    print("  no two chains' solids overlap" + (
        f", nor a chain and the payload box centred at ({', '.join(f'{v * 1e3:g}' for v in placed)}) mm" if placed
        else "; the payload box is not placed ([payload] box_centre_mm), so not checked"))
    print(f"  held in every direction by the chains' axes (weakest {ratio:.3g} of the strongest)")
    print(f"  actuator travel needed [mm]: {', '.join(f'{v * 1e3:.3g}' for v in travel)} of +-"
          f"{mechanism.actuator_half_stroke * 1e3:g} (workspace corners + x0 and clearance ranges)")
    return 0
