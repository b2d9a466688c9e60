"""The mapped hinge mesher's converged compliance against an independent reference (issue 26,
"Verification"): every dominant entry of the 6 x 6 compliance of circular notch hinges
(R 5 mm, b 10 mm, blocks 5 mm; t given), its Richardson limit on nested mapped P2-tet meshes,
the Richardson limit of 27-node hexahedra (``flexcal.fem.reference_hex``) with that limit's
own uncertainty, and their relative difference.

    python benchmarks/bench_hinge_reference.py --thickness 2.5 --mapped-levels 2 3 4 \\
        --ref-base 2 --ref-levels 2 3 4 5 --default --dir /tmp/hinge_ref

(t = 1: --mapped-levels 2 3 4 --ref-levels 1 2 3 4, the levels of its slow test since session 22
(session 17's mapped 1 2 3 were pre-asymptotic in torsion); t = 0.5: --mapped-levels 1 2 3
--ref-width 10 --ref-levels 2 3 4: the runs of docs/hinge-verification.md, "Independent
reference (session 17)" and "Session 22"; one
OMP/MKL thread; the finest levels there take 270k-570k DOF and up to ~12 GB).

Mapped: ``mapped_mesh_part``'s own pipeline (``mapped_grid`` at --mapped-base cells through,
every cell of that grid split into r^3 for r in --mapped-levels, then the mesher's snapping and
isoparametric mid-nodes; ``nested_mapped_mesh``), condensed by ``flexcal.fem.condense``.
Reference: ``hex27_hinge_compliance`` at --ref-base cells through, refinement r in
--ref-levels (nested in parameter space). Each level's h = 1 / r; ``richardson`` fits rate
and limit over three levels. The reference's limit is that of its finest three levels; its
uncertainty the difference from the limit of the three levels before them (with four or
more levels), else half the spread of the finest two levels' limits at rates p -+ 1 (printed
in parentheses in every case).

The table: entry, mapped rate and limit, reference rate, limit +- uncertainty, relative
difference 100 (mapped - reference) / |reference| [%], the finest mapped level's and (with
--default) ``flexcal hinge``'s default mesh's difference from the reference limit [%], and
"ok" when the limits agree within 0.1 %
(nothing added for the uncertainty, which is printed beside it). Each compliance is stored
as DIR/<tag>.npy and reused. Not a test (tests/test_hinge_reference.py is).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from flexcal.validation.cli.hinge import DEFAULT_CONFIG
from flexcal.validation.reports.hinge_reference import AGREEMENT, compare


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--thickness", type=float, nargs="+", default=[2.5, 1.0, 0.5], help="t [mm]")
    parser.add_argument("--mapped-base", type=int, default=2)
    parser.add_argument("--mapped-levels", type=int, nargs=3, default=[1, 2, 3])
    parser.add_argument("--ref-base", type=int, default=2)
    parser.add_argument("--ref-levels", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--ref-width", type=int, default=None, help="reference cells across the width at r = 1")
    parser.add_argument("--default", action="store_true",
                        help="also flexcal hinge's default mesh against the reference")
    parser.add_argument("--dir", default="bench_hinge_reference")
    args = parser.parse_args()
    folder = Path(args.dir).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    for t in args.thickness:
        default = DEFAULT_CONFIG["elements_through"] if args.default else None
        rows = compare(t, folder, args.mapped_base, args.mapped_levels, args.ref_base, args.ref_levels, default,
                       args.ref_width)
        print(f"\nnotch R 5, t {t:g}, b 10 mm: mapped nested at {args.mapped_base} through, r = {args.mapped_levels}; "
              f"Q2 hex reference at {args.ref_base} through, r = {args.ref_levels}")
        print("| entry | mapped rate | mapped limit | ref rate | reference limit +- uncertainty (rate p -+ 1) | "
              "mapped - ref [%] | finest mapped - ref [%] | default - ref [%] | within 0.1 % |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
        for name, p, lim, q, ref, unc, diff, finest, dflt, spread in rows:
            print(f"| {name} | {p:.2f} | {lim:.6e} | {q:.2f} | {ref:.6e} +- {100 * unc / abs(ref):.3f} % "
                  f"({100 * spread / abs(ref):.3f} %) | "
                  f"{100 * diff:+.3f} | {100 * finest:+.3f} | {100 * dflt:+.3f} | "
                  f"{'ok' if abs(diff) <= AGREEMENT else 'MISS'} |")


if __name__ == "__main__":
    main()
