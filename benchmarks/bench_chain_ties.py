"""The whole L1 and D1 chains composed from the prototype's five segments joined through the
same interface at all four cuts (m1, s0, s1, m2; issue 26, docs/meshing.md "Session 24: ties
at every cut"): every dominant entry against the chain meshed in one piece and untied (U, the
same grid with lines at the cuts), and optionally against session 20's converged estimate C
(``bench_whole_chain.whole_chain_estimate``, from the Q2-hex levels in --ref-dir); the CPU of
the segments' condensations per interface, the labels alternating (A B A B) in one process.

    python benchmarks/bench_chain_ties.py --chain L1 --interface rigid p12 d12 p10 d10 p8 d8 \\
        --rounds 2 --dir C --ref-dir D
    python benchmarks/bench_chain_ties.py --chain D1 --through 8 --interface rigid p12 d12 --dir C

The second-half segments are their first-half twins' condensations turned
(``turned_segment_stiffness``), as the prototype's; so a chain costs three condensations: the
two leaf segments [0, m1], [m1, s0] and the strut segment [s0, s1]. The strut segment's section
on the prototype's grid is 2 x 2 cells (25 face nodes): too poor for a field of order > 2 (a
distributing field's Gram matrix is singular beyond it), so it is meshed with every cell split
into --strut-refinement^3 (default 3: 13 x 13 face nodes) for every interface, rigid included;
"prototype" is the prototype's own composition (rigid ties, strut at refinement 1), timed in the
same rounds; --cost-only: only the CPU (e.g. D1 at the prototype's 7 through, whose one piece
has no mirror plane).

U and the rigidly tied one piece T are stored as DIR/untied_<tag>.npy, DIR/tied_<tag>.npy
(``bench_chain_cuts.cut_tag``, shared with bench_chain_cuts.py and bench_whole_chain.py), the
composed matrices as DIR/ties_<label>_<tag>_s<r>.npy. One OMP/MKL thread. Not a test
(tests/test_chain_cuts.py is).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from bench_chain_cuts import cut_tag, peak_gb, print_against_untied, timed_compositions
from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS
from flexcal.validation.reports.chain_cuts import (mirror_part, cut_rows, entry_index, interface_scale,
                                                   interface_segments, one_piece_stiffness, plan_key, stretch)
from flexcal.validation.reports.chain_reference import reference_chain

STRUT = 2  # the plan's index of the strut segment [s0, s1]


def one_piece(chain, name: str, through: float, change: dict, folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """(U, T) of the whole chain in one piece (untied, rigidly tied at the four cuts), stored."""
    tag = cut_tag(name, 5, through, change)
    paths = {kind: folder / f"{kind}_{tag}.npy" for kind in ("untied", "tied")}
    if not all(p.exists() for p in paths.values()):
        cpu, wall = time.process_time(), time.perf_counter()
        part, cuts = stretch(chain, 5)
        untied, (tied,), dof = one_piece_stiffness(part, cuts, through, {**PROTOTYPE_CHAIN_OPTIONS, **change})
        print(f"{name} one piece: {dof} DOF (mirror part), {time.process_time() - cpu:.1f} s CPU, "
              f"{time.perf_counter() - wall:.1f} s wall (load {os.getloadavg()[0]:.1f}), peak {peak_gb():.2f} GB",
              flush=True)
        np.save(paths["untied"], untied)
        np.save(paths["tied"], tied)
    return np.load(paths["untied"]), np.load(paths["tied"])


def cut_labels(label: str):
    """The interface at each of the four cuts (m1, s0, s1, m2) of a label: "d12" at all four;
    "d12/rigid" d12 at the mid-connector cuts m1, m2 and rigid at the strut cuts s0, s1."""
    if "/" not in label:
        return label
    middle, strut = label.split("/")
    return (middle, strut, strut, middle)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chain", nargs="+", default=["L1"])
    parser.add_argument("--through", type=float, default=7.0, help="cells asked for, segments and one piece")
    parser.add_argument("--options", default="{}", help="JSON, updates PROTOTYPE_CHAIN_OPTIONS")
    parser.add_argument("--interface", nargs="+", default=["rigid", "p12", "d12"],
                        help="labels (chain_cuts.INTERFACES, any p<p>, d<p>) at all four cuts, or m/s: m at m1, m2 "
                             "and s at s0, s1 (e.g. d12/rigid)")
    parser.add_argument("--strut-refinement", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--dir", default="bench_chain_cuts")
    parser.add_argument("--ref-dir", default=None, help="also against session 20's estimate C from these hex levels")
    parser.add_argument("--cost-only", action="store_true", help="only the condensations' CPU (no one piece, no C)")
    args = parser.parse_args()
    folder = Path(args.dir).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    change = json.loads(args.options)
    options = {**PROTOTYPE_CHAIN_OPTIONS, **change}
    labels = list(dict.fromkeys(args.interface))
    for name in args.chain:
        chain = reference_chain(name)
        tag = f"{cut_tag(name, 5, args.through, change)}_s{args.strut_refinement}"
        plan = interface_segments(chain, 5)
        scale = interface_scale(chain, 5)
        pieces = {plan_key(step)[:2]: step[0] for step in plan}  # the three meshed segments
        strut = plan_key(plan[STRUT])[:2]
        meshes = {key: mirror_part(segment, args.through, options, args.strut_refinement if key == strut else 1)
                  for key, segment in pieces.items()}
        prototype_meshes = {**meshes, strut: mirror_part(pieces[strut], args.through, options)}
        variants = {"prototype": ("rigid", prototype_meshes),
                    **{label: (cut_labels(label), meshes) for label in labels}}
        cpu, matrices = timed_compositions(plan, variants, args.rounds, scale)
        for variant, value in matrices.items():
            np.save(folder / f"ties_{variant.replace('/', '-')}_{tag}.npy", value)
        dofs = ", ".join(f"{3 * len(m.nodes)}" for m, _ in meshes.values())
        print(f"\n{name} whole chain, {args.through:g} asked for, strut refinement {args.strut_refinement} (meshed "
              f"segments' mirror parts {dofs} DOF; the prototype's strut {3 * len(prototype_meshes[strut][0].nodes)})")
        print("CPU of the condensations [s] per meshed segment and their sum, median of "
              f"{args.rounds} rounds (ratio to the prototype's: rigid ties, strut refinement 1)")
        print("| variant | " + " | ".join(f"[{1e3 * a:g}, {1e3 * b:g}] mm" for a, b in pieces) + " | sum |")
        print("|---|" + "---:|" * (len(pieces) + 1))
        base = {key: np.median(t) for key, t in cpu["prototype"].items()}
        total = sum(base.values())
        for variant, times in cpu.items():
            medians = {key: np.median(t) for key, t in times.items()}
            print(f"| {variant} | " + " | ".join(f"{medians[key]:.2f} ({medians[key] / base[key]:.2f})" for key in pieces)
                  + f" | {sum(medians.values()):.2f} ({sum(medians.values()) / total:.2f}) |")
        if args.cost_only:
            continue
        untied, tied = one_piece(chain, name, args.through, change, folder)
        prototype = matrices["prototype"]
        rows = cut_rows(prototype, tied, untied)
        print(f"\n{name}: composed through each interface at the four cuts - U [%]; 'prototype' its own rigid "
              "composition, 'T' the one piece rigidly tied")
        print_against_untied({"T": tied, **matrices}, untied, rows)
        if args.ref_dir:
            from bench_whole_chain import whole_chain_estimate

            estimate = whole_chain_estimate(name, args.through, change, Path(args.ref_dir).resolve(), folder,
                                            [2, 3, 4, 5, 6], [3, 4, 5, 6] if name.startswith("L") else [2, 3, 4, 5],
                                            [4, 5, 6])
            converged = estimate["converged"]
            print(f"\n{name}: against session 20's estimate C (bench_whole_chain.py), (K - C) / |C| [%]; U - C is the "
                  "one piece's own discretisation")
            print("| entry | C | " + " | ".join(["U", *matrices]) + " |")
            print("|---|---:|" + "---:|" * (len(labels) + 2))
            for entry, *_ in rows:
                i, j = entry_index(entry)
                values = [untied, *matrices.values()]
                print(f"| {entry} | {converged[i, j]:.6e} | "
                      + " | ".join(f"{100 * (k[i, j] - converged[i, j]) / abs(converged[i, j]):+.3f}" for k in values)
                      + " |")
        print(f"peak {peak_gb():.2f} GB", flush=True)


if __name__ == "__main__":
    main()
