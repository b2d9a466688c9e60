"""``flexcal chain``: FEM vs analytic (paper Eq. 1) stiffness of one flexure chain.

Writes DIR/report.json (``stiffness_fem``, ``stiffness_analytic`` 12 x 12 between the end
faces A and B; ``compliance_fem``, ``compliance_analytic`` 6 x 6 at B with A clamped and
their per-entry % difference; mesh), DIR/timings.json (wall/CPU seconds per stage),
DIR/report.md, DIR/chain.vtu, DIR/chain.png, DIR/chain-mesh.png.
"""

from __future__ import annotations

import argparse
import dataclasses

from .options import add_out

__all__ = ["configure", "run", "EXAMPLES", "DEFAULT_CONFIG"]

EXAMPLES = (
    "flexcal chain --reference D1 --out runs/chain-d1          # ~1 min",
    "flexcal chain --length-mm 150 --t1-mm 3 --out runs/chain",
    "flexcal chain --mount my.mount.toml --reference L2 --out runs/chain-l2   # a chain of your mount",
    "flexcal report runs/chain-d1",
)
DEFAULT_CONFIG = {"elements_through": 7.0, "mesher": "mapped"}


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--reference", metavar="CHAIN",
                        help="start from chain CHAIN (L1-L3, D1-D3) of the mount (--mount FILE, else the reference "
                             "mechanism); the options below override it")
    from .options import add_mount

    add_mount(parser, what="the reference mechanism, for --reference")
    parser.add_argument("--length-mm", type=float, help="distance between the end faces A and B [mm]")
    parser.add_argument("--hinge-length-mm", type=float, help="leaf segment length l [mm] (default 20)")
    parser.add_argument("--width-mm", type=float, help="leaf width w [mm] (default 40)")
    parser.add_argument("--fillet-mm", type=float, help="fillet radius a [mm] (default 6)")
    parser.add_argument("--t1-mm", type=float, help="thickness of leaf 1, thin in local y [mm] (default 4)")
    parser.add_argument("--t2-mm", type=float, help="thickness of leaf 2, thin in local z [mm] (default 4)")
    parser.add_argument("--section-mm", type=float, help="square section of blocks and strut [mm] (default 50)")
    parser.add_argument("--elements-through", type=float,
                        help="quadratic tets through the thinnest leaf (default %(default)s: every dominant "
                             "stiffness entry of the prototype's leaf segments within 0.5 %% of converged with the mapped "
                             "mesher, which raises it for stubby leaves; docs/meshing.md)")
    parser.add_argument("--mesher", choices=("mapped", "tetwild"),
                        help="mapped multi-block mesh (default %(default)s: the same mesh on every machine) or "
                             "fTetWild")
    add_out(parser, what="report.json, timings.json, report.md, chain.png, chain-mesh.png, chain.vtu")


_FIELDS = {"length_mm": "length", "hinge_length_mm": "hinge_length", "width_mm": "width", "fillet_mm": "fillet",
           "t1_mm": "thickness_1", "t2_mm": "thickness_2", "section_mm": "section"}


def build_chain(args: argparse.Namespace):
    from flexcal.geometry.params import FlexureChain, reference_mechanism

    from .input_checks import check_length_mm

    for option in _FIELDS:
        check_length_mm("--" + option.replace("_", "-"), getattr(args, option), allow_zero=option == "fillet_mm")
    changes = {field: getattr(args, option) * 1e-3 for option, field in _FIELDS.items()
               if getattr(args, option) is not None}
    from .options import mount_option

    mount = mount_option(args)
    if mount is not None and args.reference is None:
        raise ValueError(f"--mount {args.mount} needs --reference CHAIN: which of its chains "
                         f"({', '.join(c.name for c in mount.chains)})")
    if args.reference is not None:
        chains = {c.name: c for c in (mount or reference_mechanism()).chains}
        if args.reference not in chains:
            raise ValueError(f"--reference {args.reference!r} is no chain of the mount; choose one of "
                             f"{', '.join(chains)}")
        placement = chains[args.reference]
        chain = dataclasses.replace(placement.chain, **changes)
    else:
        if "length" not in changes:
            raise ValueError("give --length-mm (or --reference L1..D3)")
        chain = FlexureChain(**changes)
    params = {option.removesuffix("_mm"): getattr(chain, field) * 1e3 for option, field in _FIELDS.items()}
    return chain, params


def run(args: argparse.Namespace) -> int:
    from .common import show_progress
    from ..reports.fem import compare_chain, run_comparison

    from .input_checks import check_elements_through

    check_elements_through(args.elements_through)
    chain, params = build_chain(args)  # validates before any CAD or meshing
    result, data = run_comparison(compare_chain, chain, params, args.out,
                                  elements_through_thickness=args.elements_through, mesher=args.mesher,
                                  progress=show_progress(args),
                                  cache=True, replace=args.force)
    print(f"flexcal chain: largest diagonal compliance difference FEM vs Eq. 1 "
          f"{data['max_abs_percent_difference_diagonal']:.1f} %; {data['mesh']['n_dof']} DOF, "
          f"{sum(result.timings.values()):.1f} s; wrote {args.out}/report.json, timings.json, report.md, "
          f"chain.vtu, chain.png, chain-mesh.png")
    return 0
