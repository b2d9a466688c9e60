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
"prototype P" is the prototype's own composition (rigid ties, strut at refinement 1).

U and the rigidly tied one piece T are stored as DIR/untied_<tag>.npy, DIR/tied_<tag>.npy
(``bench_chain_cuts.cut_tag``, shared with bench_chain_cuts.py and bench_whole_chain.py), the
composed matrices as DIR/ties_<label>_<tag>_s<r>.npy. One OMP/MKL thread. Not a test
(tests/test_chain_cuts.py is).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
from pathlib import Path

import numpy as np

from bench_chain_cuts import cut_tag, print_against_untied
from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS
from flexcal.validation.reports.chain_cuts import (_mirror_part, composed_stiffness, cut_rows, entry_index,
                                                   interface_condensations, interface_scale,
                                                   interface_segment_stiffness, interface_segments,
                                                   joined_through_interface, one_piece_stiffness, plan_key, stretch)
from flexcal.validation.reports.chain_reference import reference_chain

STRUT = 2  # the plan's index of the strut segment [s0, s1]


def peak_gb() -> float:
    """This process's peak resident memory so far [GB]."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chain", nargs="+", default=["L1"])
    parser.add_argument("--through", type=float, default=7.0, help="cells asked for, segments and one piece")
    parser.add_argument("--options", default="{}", help="JSON, updates PROTOTYPE_CHAIN_OPTIONS")
    parser.add_argument("--interface", nargs="+", default=["rigid", "p12", "d12"])
    parser.add_argument("--strut-refinement", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--dir", default="bench_chain_cuts")
    parser.add_argument("--ref-dir", default=None, help="also against session 20's estimate C from these hex levels")
    args = parser.parse_args()
    folder = Path(args.dir).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    change = json.loads(args.options)
    options = {**PROTOTYPE_CHAIN_OPTIONS, **change}
    labels = list(dict.fromkeys(args.interface))
    for name in args.chain:
        chain = reference_chain(name)
        untied, tied = one_piece(chain, name, args.through, change, folder)
        tag = f"{cut_tag(name, 5, args.through, change)}_s{args.strut_refinement}"
        prototype = composed_stiffness(chain, 5, args.through, options)
        plan = interface_segments(chain, 5)
        scale = interface_scale(chain, 5)
        jobs = interface_condensations(plan)
        meshes = {key: _mirror_part(segment, args.through, options,
                                    args.strut_refinement if key == plan_key(plan[STRUT]) else 1)
                  for key, (segment, _, _) in jobs.items()}
        cpu = {label: [] for label in labels}
        matrices = {}
        for _ in range(args.rounds):
            for label in labels:  # A B A B: every label once per round
                start, condensed = time.process_time(), {}
                for key, (segment, starts, ends) in jobs.items():
                    condensed[key] = interface_segment_stiffness(segment, meshes[key], starts, ends, label, scale)
                cpu[label].append(time.process_time() - start)
                matrices[label] = joined_through_interface(plan, condensed, label)
            print(f"round done (load {os.getloadavg()[0]:.1f}, peak {peak_gb():.2f} GB)", flush=True)
        for label, value in matrices.items():
            np.save(folder / f"ties_{label}_{tag}.npy", value)
        rows = cut_rows(prototype, tied, untied)
        dofs = ", ".join(f"{3 * len(m.nodes)}" for m, _ in meshes.values())
        print(f"\n{name} whole chain, {args.through:g} asked for, strut refinement {args.strut_refinement} "
              f"(meshed segments' mirror parts {dofs} DOF), composed through each interface at the four cuts - U "
              f"[%]; 'prototype' its own rigid composition, 'T' the one piece rigidly tied")
        print_against_untied({"prototype": prototype, "T": tied, **matrices}, untied, rows)
        base = np.median(cpu[labels[0]])
        print(f"\nCPU of the three condensations [s], median of {args.rounds} (ratio to {labels[0]}): "
              + ", ".join(f"{label} {np.median(t):.2f} ({np.median(t) / base:.2f})" for label, t in cpu.items()))
        if args.ref_dir:
            from bench_whole_chain import whole_chain_estimate

            estimate = whole_chain_estimate(name, args.through, change, Path(args.ref_dir).resolve(), folder,
                                            [2, 3, 4, 5, 6], [3, 4, 5, 6] if name.startswith("L") else [2, 3, 4, 5],
                                            [4, 5, 6])
            converged = estimate["converged"]
            print(f"\n{name}: against session 20's estimate C (bench_whole_chain.py), (K - C) / |C| [%]; U - C is the "
                  "one piece's own discretisation")
            print("| entry | C | " + " | ".join(["U", "prototype", *labels]) + " |")
            print("|---|---:|" + "---:|" * (len(labels) + 2))
            for entry, *_ in rows:
                i, j = entry_index(entry)
                values = [untied, prototype, *(matrices[label] for label in labels)]
                print(f"| {entry} | {converged[i, j]:.6e} | "
                      + " | ".join(f"{100 * (k[i, j] - converged[i, j]) / abs(converged[i, j]):+.3f}" for k in values)
                      + " |")
        print(f"peak {peak_gb():.2f} GB", flush=True)


if __name__ == "__main__":
    main()
