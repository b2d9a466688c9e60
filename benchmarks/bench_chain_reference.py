"""The mapped chain mesher's converged stiffness of the prototype's leaf segments against an
independent reference (issue 26, "Verification"): every dominant entry of the 12 x 12
stiffness of the [0, m1] or [m1, s0] segment of L1 or D1, its Richardson limit on nested
mapped P2-tet meshes (``bench_chain_convergence.py``'s nested study: 2 through, session 13's
grid, every cell split into r^3), the Richardson limit of 27-node hexahedra
(``flexcal.fem.reference_hex_chain``) with that limit's own uncertainty, their relative
difference, and the virtual prototype's mesh (``segment_stiffness_fem``) against the
reference limit.

    python benchmarks/bench_chain_reference.py --chain L1 --mapped-levels 2 3 4 \\
        --ref-levels 2 3 4 5 6 --prototype --dir /tmp/chain_ref
    python benchmarks/bench_chain_reference.py --chain L1 D1 --mirrored --mapped-levels 2 3 4 \\
        --ref-levels 2 3 4 5 6 --prototype --dir /tmp/chain_ref
    python benchmarks/bench_chain_reference.py --chain L1 D1 --segment 1 --mirrored \\
        --mapped-levels 2 3 4 --ref-levels 2 3 4 5 --prototype --dir /tmp/chain_ref
    python benchmarks/bench_chain_reference.py --chain L1 --segment 1 --mirrored \
        --mapped-levels 4 5 6 --ref-levels 3 4 5 6 --prototype --prototype-options '{"n_arc": 7}' --dir /tmp/chain_ref

--mirrored: the mapped levels condensed on their quarter (``mapped_stiffness``; D1's whole
level r = 4, 727k DOF, needs more than 8 GB). The finest reference level, r = 6, is 474k DOF
and 6.4 GB. Every matrix is read from DIR/<tag>.npy when it is there (a reference level computed
once serves every later run: copy the hex27_*.npy of an earlier run into DIR); --prototype-options
compares a candidate grid for the prototype (PROTOTYPE_CHAIN_OPTIONS updated by the JSON given).

The reference's limit is that of its finest three levels; its uncertainty the difference
from the limit of the three levels before them (with four or more levels), else half the
spread of the finest two levels' limits at rates p -+ 1 (printed in parentheses in every
case). "ok" when the limits agree within 0.1 % (nothing added for the uncertainty). Each
matrix is stored as DIR/<tag>.npy and reused. One OMP/MKL thread; docs/meshing.md
("Independent reference: Q2 hexahedra") gives the runs, their DOF, time and memory. Not a
test (tests/test_chain_reference.py is).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from flexcal.validation.reports.chain_reference import AGREEMENT, compare


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chain", nargs="+", default=["L1"])
    parser.add_argument("--segment", type=int, default=0, help="0: [0, m1], 1: [m1, s0]")
    parser.add_argument("--mapped-levels", type=int, nargs=3, default=[2, 3, 4])
    parser.add_argument("--ref-levels", type=int, nargs="+", default=[2, 3, 4, 5, 6])
    parser.add_argument("--prototype", action="store_true", help="also the prototype's segment mesh")
    parser.add_argument("--mirrored", action="store_true",
                        help="mapped levels condensed on their quarter (D1's r = 4 whole needs > 8 GB)")
    parser.add_argument("--prototype-options", default=None,
                        help="JSON: the prototype's mesh on PROTOTYPE_CHAIN_OPTIONS updated by these (a candidate grid)")
    parser.add_argument("--dir", default="bench_chain_reference")
    args = parser.parse_args()
    folder = Path(args.dir).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    candidate = None
    if args.prototype_options is not None:
        from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS

        candidate = {**PROTOTYPE_CHAIN_OPTIONS, **json.loads(args.prototype_options)}
    for chain in args.chain:
        rows = compare(chain, folder, args.mapped_levels, args.ref_levels, args.prototype, args.mirrored,
                       args.segment, candidate)
        name = ("[0, m1]", "[m1, s0]")[args.segment]
        print(f"\n{chain} {name}: mapped nested at 2 through{', mirrored' if args.mirrored else ''}, "
              f"r = {args.mapped_levels}; "
              f"Q2 hex reference r = {args.ref_levels}")
        print("| entry | mapped rate | mapped limit | ref rate | reference limit +- uncertainty (rate p -+ 1) | "
              "mapped - ref [%] | finest mapped - ref [%] | prototype - ref [%] | within 0.1 % |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
        for name, p, lim, q, ref, unc, diff, finest, proto, spread in rows:
            print(f"| {name} | {p:.2f} | {lim:.6e} | {q:.2f} | {ref:.6e} +- {100 * unc / abs(ref):.3f} % "
                  f"({100 * spread / abs(ref):.3f} %) | {100 * diff:+.3f} | {100 * finest:+.3f} | "
                  f"{100 * proto:+.3f} | {'ok' if abs(diff) <= AGREEMENT else 'MISS'} |")


if __name__ == "__main__":
    main()
