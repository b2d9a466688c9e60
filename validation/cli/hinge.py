"""``flexcal hinge``: FEM vs closed-form 6 x 6 compliance of one flexure hinge.

Writes DIR/report.json (``compliance_fem``, ``compliance_analytic``, per-entry %
difference, mesh size and quality), DIR/timings.json (wall/CPU seconds per stage),
DIR/report.md, DIR/hinge.vtu, DIR/hinge.png and DIR/hinge-mesh.png.
"""

from __future__ import annotations

import argparse

from .options import add_out

__all__ = ["configure", "run", "EXAMPLES", "DEFAULT_CONFIG"]

EXAMPLES = (
    "flexcal hinge --type circular --radius-mm 5 --thickness-mm 1 --width-mm 10 --out runs/hinge",
    "flexcal hinge --type leaf --length-mm 20 --thickness-mm 4 --width-mm 40 --fillet-mm 6 --out runs/leaf",
    "flexcal report runs/hinge        # -> runs/hinge/report.html",
)
DEFAULT_CONFIG = {"elements_through": 3.0, "mesher": "mapped"}


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--type", choices=("circular", "leaf"), required=True,
                        help="circular notch hinge, or corner-filleted leaf hinge (paper Fig. 5c)")
    parser.add_argument("--thickness-mm", type=float, required=True, help="minimum thickness t [mm]")
    parser.add_argument("--width-mm", type=float, required=True, help="width b / w [mm]")
    parser.add_argument("--radius-mm", type=float, help="notch radius R [mm] (circular)")
    parser.add_argument("--length-mm", type=float, help="segment length l including fillets [mm] (leaf)")
    parser.add_argument("--fillet-mm", type=float, default=0.0, help="fillet radius a [mm] (leaf; default 0)")
    parser.add_argument("--block-mm", type=float, default=None,
                        help="length of the rigid block at each end [mm] (default: R, or l/2 for a leaf)")
    parser.add_argument("--elements-through", type=float,
                        help="quadratic tets through the thinnest section, 1 to 16 (default %(default)s: C_rz,Mz "
                             "within ~0.6 %% of converged with the mapped mesh, ~0.3 %% with tetwild; 4 gives ~0.3 %% "
                             "mapped; the mapped mesher rounds up to whole cells)")
    parser.add_argument("--mesher", choices=("mapped", "tetwild"),
                        help="mapped: a structured mesh mapped onto the hinge's profile, the same mesh and numbers "
                             "on every run; tetwild: fTetWild, a different random mesh per solve (default "
                             "%(default)s). Either way the result goes to the FEM cache")
    add_out(parser, what="report.json, timings.json, report.md, hinge.png, hinge-mesh.png, hinge.vtu")


def build_hinge(args: argparse.Namespace):
    from flexcal.geometry.params import CircularNotchHinge, LeafHinge

    from .input_checks import check_length_mm

    for option in ("thickness_mm", "width_mm", "radius_mm", "length_mm", "block_mm"):
        check_length_mm("--" + option.replace("_", "-"), getattr(args, option))
    check_length_mm("--fillet-mm", args.fillet_mm, allow_zero=True)
    mm = 1e-3
    if args.type == "circular":
        if args.radius_mm is None:
            raise ValueError("--type circular needs --radius-mm")
        block = args.radius_mm if args.block_mm is None else args.block_mm
        hinge = CircularNotchHinge(radius=args.radius_mm * mm, thickness=args.thickness_mm * mm,
                                   width=args.width_mm * mm, block_length=block * mm)
        params = {"radius": args.radius_mm, "thickness": args.thickness_mm, "width": args.width_mm, "block": block}
    else:
        if args.length_mm is None:
            raise ValueError("--type leaf needs --length-mm")
        block = args.length_mm / 2 if args.block_mm is None else args.block_mm
        hinge = LeafHinge(length=args.length_mm * mm, thickness=args.thickness_mm * mm, width=args.width_mm * mm,
                          fillet=args.fillet_mm * mm, block_length=block * mm)
        params = {"length": args.length_mm, "thickness": args.thickness_mm, "width": args.width_mm,
                  "fillet": args.fillet_mm, "block": block}
    return hinge, params


def warn_outside_closed_form_range(hinge) -> None:
    """One warning line per closed-form validity range of the working rotation the hinge
    leaves (stderr, logging); report.json lists the torsion note as well."""
    import logging

    from flexcal.model.hinge import closed_form_range_warnings

    for text in closed_form_range_warnings(hinge, torsion=False):
        logging.getLogger("flexcal.hinge").warning(text)


def run(args: argparse.Namespace) -> int:
    from .common import show_progress
    from ..reports.fem import compare_hinge, run_comparison

    from .input_checks import check_elements_through

    check_elements_through(args.elements_through)
    hinge, params = build_hinge(args)  # validates before any CAD or meshing
    warn_outside_closed_form_range(hinge)
    result, data = run_comparison(compare_hinge, hinge, params, args.out,
                                  elements_through_thickness=args.elements_through, progress=show_progress(args),
                                  mesher=args.mesher, cache=True, replace=args.force)
    c_fem, c_ana = result.compliance_fem[5, 5], result.compliance_analytic[5, 5]
    print(f"flexcal hinge: C_rz,Mz FEM {c_fem:.6g} rad/(N m), closed form {c_ana:.6g} "
          f"({100 * (c_fem - c_ana) / c_ana:+.2f} %); largest diagonal difference "
          f"{data['max_abs_percent_difference_diagonal']:.1f} %; {data['mesh']['n_dof']} DOF, "
          f"{sum(result.timings.values()):.1f} s; wrote {args.out}/report.json, timings.json, report.md, "
          f"hinge.vtu, hinge.png, hinge-mesh.png")
    return 0
