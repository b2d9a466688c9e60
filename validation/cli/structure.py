"""``flexcal structure``: the mount as a structure (modes, support stiffness, stress, buckling).

On the virtual prototype's reduced model at the nominal state (design commands, the
payload's weight): the first mount modes [Hz] with effective masses, the 6 x 6 support
stiffness at O_C with the actuator nuts held, the peak von Mises stress per chain
(nominal and over the standard trajectory) against the material's yield strength, and
buckling factors (the mount, each chain); the workspace corners, stress-limited strokes.
Writes DIR/report.json, DIR/timings.json, DIR/report.md, DIR/mode_1.png .. mode_6.png
and DIR/modes.vtu. docs/structure.md says what each figure means and how far to trust it.
"""

from __future__ import annotations

import argparse

from .options import add_out

__all__ = ["configure", "run", "EXAMPLES"]

EXAMPLES = (
    "flexcal structure --out runs/structure                  # beam-theory segments, ~7 s of CPU",
    "flexcal structure --segments fem --out runs/structure-fem  # meshed segments (mapped), ~1 min of CPU cold, cached",
    "flexcal structure --segments fem --mesher tetwild --out runs/structure-tw  # fTetWild segments, ~5 min cold",
    "flexcal structure --segments fem --provider fem --out runs/structure-truth  # the truth's frame (cuts tied)",
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--segments", choices=("analytic", "fem"), default="analytic",
                        help="chain segments from beam theory (default, seconds) or meshed and Guyan-reduced "
                             "(minutes the first time, then from the FEM cache)")
    parser.add_argument("--mesher", choices=("mapped", "tetwild"), default="mapped",
                        help="FEM segments: the deterministic mapped multi-block mesh (default) or fTetWild on the "
                             "CAD solid")
    parser.add_argument("--elements-through", type=float,
                        help="FEM segments: cells through the thinnest leaf (default: mapped 6, tetwild 2)")
    parser.add_argument("--refine", action="store_true",
                        help="FEM segments: the driving chains' workspace stresses again one mesh refinement finer "
                             "(mapped: 2 more cells through the leaves, tetwild: 1 more; built once, then cached)")
    from .options import worker_count

    parser.add_argument("--workers", type=worker_count, metavar="N", default=None,
                        help="FEM segments: build threads (default: one per usable core, memory permitting; 0: one "
                             "after the other in this process)")
    from ..prototype.providers import PROVIDERS

    parser.add_argument("--provider", choices=PROVIDERS,
                        help="the prototype's stiffness from the truth's provider instead of the segments' own "
                             "(fem: each chain's cuts tied through section fields, docs/structure.md \"Tied cuts\"; "
                             "fem-rigid: tied rigidly); masses and stress fields stay the segments'")
    parser.add_argument("--modes", type=int, default=12, help="number of mount modes (default %(default)s)")
    parser.add_argument("--trajectory-points", type=int, default=77,
                        help="points of the standard trajectory the stresses are taken over (1 + a multiple of 4, >= 13; 0: nominal only; "
                             "default %(default)s)")
    from .options import add_mount

    add_mount(parser, what="the reference mount")
    add_out(parser, what="report.json, timings.json, report.md, mode_*.png, modes.vtu")


def run(args: argparse.Namespace) -> int:
    from flexcal.geometry.params import reference_mechanism

    from ..output import staged_output, write_report, write_text
    from ..structure.report import markdown, structure_report
    from .common import show_progress
    from .input_checks import check_elements_through

    if args.elements_through is not None:
        check_elements_through(args.elements_through)
    if args.segments != "fem" and (args.mesher != "mapped" or args.elements_through is not None):
        raise ValueError("--mesher and --elements-through need --segments fem (beam-theory segments have no mesh)")
    if args.refine and args.segments != "fem":
        raise ValueError("--refine needs --segments fem (beam-theory stresses have no mesh to refine)")
    if args.modes < 1:
        raise ValueError(f"--modes {args.modes} must be >= 1")
    if args.trajectory_points < 0:
        raise ValueError(f"--trajectory-points {args.trajectory_points} must be >= 0")
    with staged_output(args.out, replace=args.force) as staging:
        from .options import mount_option

        report = structure_report(mount_option(args) or reference_mechanism(), segments=args.segments,
                                  elements_through=args.elements_through, mesher=args.mesher, n_modes=args.modes,
                                  trajectory_points=args.trajectory_points, refine=args.refine, figures=staging,
                                  progress=show_progress(args), workers=args.workers, provider=args.provider)
        write_report(staging, report)
        write_text(staging / "report.md", markdown(report))
    f = report["modes"]["frequencies_Hz"]
    safety = report["stress"]["safety_factor_against_yield"]
    worst = min(safety, key=safety.get)
    print(f"flexcal structure: first mode {f[0]:.1f} Hz; lowest safety against yield {safety[worst]:.2f} ({worst}); "
          f"mount buckling factor {report['buckling']['mount_weight_factor']:.1f}; wrote {args.out}/report.json, "
          "timings.json, report.md")
    return 0
