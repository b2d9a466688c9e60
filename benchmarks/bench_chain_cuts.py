"""What cutting the prototype's chains into rigidly tied segments does (issue 26, whole
chains): every dominant entry of the 12 x 12 of the first k segments of L1 or D1
(``--segments 2``: [0, s0], the two leaf segments; 5: the whole chain) composed from the
segments meshed alone (the prototype's way), against the same stretch meshed in one piece
(grid lines at the cuts), with the cut sections rigidly tied (tied) and without (untied):
``flexcal.validation.reports.chain_cuts``.

    python benchmarks/bench_chain_cuts.py --chain L1 D1 --segments 2 --dir /tmp/cuts
    python benchmarks/bench_chain_cuts.py --chain L1 --segments 5 --tie 0,3 1,2 --dir /tmp/cuts
    python benchmarks/bench_chain_cuts.py --chain L1 --middle --dir /tmp/cuts   # one cut, at L/2
    python benchmarks/bench_chain_cuts.py --chain L1 --strut-depth 50 --dir /tmp/cuts   # 50 mm into the strut
    python benchmarks/bench_chain_cuts.py --chain L1 --segments 2 --through 10 \\
        --options '{"slenderness": null}' --dir /tmp/cuts
    python benchmarks/bench_chain_cuts.py --chain L1 D1 --segments 2 --dir /tmp/cuts \\
        --interface rigid p2 p4 p6 p8 p10 p12 d-rigid d4 d8 d10 d12 --rounds 3 --one-piece   # richer ties

--interface: the segments also joined through other interfaces at their cuts
(``chain_cuts.INTERFACES``, docs/meshing.md "Session 23"), each against the one piece untied,
with the CPU of each segment's condensation (its mirror part meshed once; assembly,
factorisation and solve), the labels alternating in each of --rounds rounds (A B A B);
--one-piece: also the one-piece mesh tied by each (distributing: cut apart there), the exact
bracket of the untied one (docs/meshing.md, "Session 23").

Options: ``PROTOTYPE_CHAIN_OPTIONS`` updated by --options (JSON); --through: cells asked for
(7, the prototype's). Each matrix is stored as DIR/<tag>.npy and reused. One OMP/MKL
thread; docs/meshing.md ("Session 20: whole chains") gives the runs. Not a test
(tests/test_chain_cuts.py is).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
import zlib
from pathlib import Path

import numpy as np

from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS
from flexcal.validation.reports.chain_cuts import (INTERFACES, mirror_part, composed_stiffness, cut_rows,
                                                     entry_index, interface_condensations, interface_scale,
                                                     interface_segment_stiffness, interface_segments,
                                                     joined_through_interface, middle_cut, one_piece_stiffness,
                                                     one_piece_tied_stiffness, plan_key, stretch, strut_cuts)
from flexcal.validation.reports.chain_reference import reference_chain


def cut_tag(name: str, n_segments, through: float, change: dict) -> str:
    """The stored matrices' name: chain, segments, cells asked for, a checksum of the options' change."""
    return f"{name}_{n_segments}_n{through:g}_{zlib.crc32(json.dumps(change, sort_keys=True).encode()):08x}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chain", nargs="+", default=["L1", "D1"])
    parser.add_argument("--segments", type=int, default=2, help="2: [0, s0]; 5: the whole chain")
    parser.add_argument("--through", type=float, default=7.0)
    parser.add_argument("--options", default="{}", help="JSON, updates PROTOTYPE_CHAIN_OPTIONS")
    parser.add_argument("--tie", nargs="*", default=None,
                        help="also the stretch with only these cuts tied (indices into the cuts, comma separated "
                             "per set, e.g. 0,3 1,2 for the whole chain: m1 and m2 alone, s0 and s1 alone)")
    parser.add_argument("--middle", action="store_true",
                        help="the whole chain cut once, at its middle (two mirror-image halves), instead of the "
                             "prototype's section nodes; --segments is ignored")
    parser.add_argument("--strut-depth", type=float, default=None,
                        help="[mm] the whole chain cut only in its strut, this far from either end of it "
                             "(three segments); --segments is ignored")
    parser.add_argument("--interface", nargs="*", default=None,
                        help=f"also join the segments through these interfaces at the cuts (first-half stretches): "
                             f"{', '.join(INTERFACES)}, or any order p<p>, d<p>")
    parser.add_argument("--rounds", type=int, default=2, help="--interface: rounds of timing, labels alternating")
    parser.add_argument("--one-piece", action="store_true",
                        help="--interface: also the one-piece mesh tied by each (the exact bracket: kinematic above "
                             "the untied, distributing below)")
    parser.add_argument("--dir", default="bench_chain_cuts")
    args = parser.parse_args()
    folder = Path(args.dir).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    change = json.loads(args.options)
    options = {**PROTOTYPE_CHAIN_OPTIONS, **change}
    for name in args.chain:
        chain = reference_chain(name)
        if args.middle or args.strut_depth is not None:
            part, cuts = middle_cut(chain) if args.middle else strut_cuts(chain, 1e-3 * args.strut_depth)
            n_segments, nodes = len(cuts) + 1, (0.0, *cuts, part.x_end)
            label = "mid" if args.middle else f"strut{args.strut_depth:g}"
        else:
            (part, cuts), n_segments, nodes, label = stretch(chain, args.segments), args.segments, None, args.segments
        tag = cut_tag(name, label, args.through, change)
        subsets = [tuple(int(i) for i in text.split(",")) for text in (args.tie or [])]
        tie_sets = [cuts] + [tuple(cuts[i] for i in subset) for subset in subsets]
        kinds = ["composed", "untied", "tied"] + [f"tied{''.join(map(str, subset))}" for subset in subsets]
        paths = {kind: folder / f"{kind}_{tag}.npy" for kind in kinds}
        if not all(p.exists() for p in paths.values()):
            cpu, wall = time.process_time(), time.perf_counter()
            untied, tied, dof = one_piece_stiffness(part, cuts, args.through, options, tie_sets)
            print(f"{name} one piece: {dof} DOF (mirror part), {len(tie_sets) + 1} condensations, "
                  f"{time.process_time() - cpu:.1f} s CPU, {time.perf_counter() - wall:.1f} s wall "
                  f"(load {os.getloadavg()[0]:.1f})", flush=True)
            cpu = time.process_time()
            composed = composed_stiffness(chain, n_segments, args.through, options, nodes)
            print(f"{name} composed: {time.process_time() - cpu:.1f} s CPU", flush=True)
            for kind, value in zip(kinds, [composed, untied, *tied]):
                np.save(paths[kind], value)
        composed, untied, *tied = (np.load(paths[k]) for k in kinds)
        print(f"\n{name} [0, {1e3 * part.x_end:.1f} mm], cuts at {[round(1e3 * c, 1) for c in cuts]} mm, "
              f"{args.through:g} asked for, options {change or 'PROTOTYPE_CHAIN_OPTIONS'}")
        only = "".join(f" only {[round(1e3 * c, 1) for c in ties]} tied - untied [%] |" for ties in tie_sets[1:])
        print(f"| entry | one piece, untied | composed - untied [%] | tied - untied [%] | composed - tied [%] |{only}")
        print("|---|---:|---:|---:|---:|" + "---:|" * len(subsets))
        for entry, value, composed_diff, tied_diff, grid_diff in cut_rows(composed, tied[0], untied):
            i, j = entry_index(entry)
            extra = "".join(f" {100 * (t[i, j] - untied[i, j]) / abs(untied[i, j]):+.3f} |" for t in tied[1:])
            print(f"| {entry} | {value:.6e} | {100 * composed_diff:+.3f} | {100 * tied_diff:+.3f} | "
                  f"{100 * grid_diff:+.3f} |{extra}")
        if args.interface:
            interfaces(chain, name, args, options, untied, composed, cut_rows(composed, tied[0], untied),
                       folder, tag)


def interfaces(chain, name, args, options, untied, composed, rows, folder, tag) -> None:
    """The stretch joined through each of ``args.interface`` at its cuts: the dominant entries
    (``rows``) against the one piece untied, and each segment's condensation CPU [s]."""
    labels = list(dict.fromkeys(args.interface))
    plan = interface_segments(chain, args.segments)
    pieces = {plan_key(step)[:2]: step[0] for step in plan}  # a second-half segment is its twin, turned
    scale = interface_scale(chain, args.segments)
    meshes = {key: mirror_part(segment, args.through, options) for key, segment in pieces.items()}
    cpu, matrices = timed_compositions(plan, {label: (label, meshes) for label in labels}, args.rounds, scale)
    for label, value in matrices.items():
        np.save(folder / f"interface_{label}_{tag}.npy", value)
    if "rigid" in matrices:
        gap = np.max(np.abs(matrices["rigid"] - composed) / np.sqrt(np.outer(np.diag(composed), np.diag(composed))))
        print(f"\nrigid through the interface code against the prototype's composed: {gap:.1e} (largest, "
              "relative to the diagonals' geometric mean)")
    dofs = [f"{3 * len(mesh.nodes)}" for mesh, _ in meshes.values()]
    print(f"\n{name} [0, {1e3 * plan[-1][0].x_end:.1f} mm] joined through each interface, composed - untied [%] "
          f"(segments' mirror parts {', '.join(dofs)} DOF, scale {1e3 * scale:g} mm)")
    print_against_untied(matrices, untied, rows)
    if args.one_piece:
        part, cuts = stretch(chain, args.segments)
        tied = {}
        for label in labels:
            path = folder / f"onepiece_{label}_{tag}.npy"
            if not path.exists():
                start = time.process_time()
                np.save(path, one_piece_tied_stiffness(part, cuts, args.through, options, label))
                print(f"one piece tied by {label}: {time.process_time() - start:.1f} s CPU", flush=True)
            tied[label] = np.load(path)
        print(f"\n{name}: the one-piece mesh tied by each interface (distributing: cut apart there), "
              "tied - untied [%]")
        print_against_untied(tied, untied, rows)
    reference = "rigid" if "rigid" in cpu else labels[0]
    base = {key: np.median(times) for key, times in cpu[reference].items()}
    print(f"\nCPU per segment condensation [s], median of {args.rounds} (ratio to {reference})")
    print("| interface | " + " | ".join(f"[{1e3 * a:g}, {1e3 * b:g}] mm" for a, b in pieces) + " |")
    print("|---|" + "---:|" * len(pieces))
    for label in labels:
        print(f"| {label} | " + " | ".join(f"{np.median(t):.2f} ({np.median(t) / base[key]:.2f})"
                                           for key, t in cpu[label].items()) + " |")


def timed_compositions(plan, variants: dict, rounds: int, scale: float) -> tuple[dict, dict]:
    """({variant: {(x_start, x_end): [CPU s per round]}}, {variant: joined 12 x 12}) of the
    stretch ``plan`` (``interface_segments``) for each variant (interface label or one per cut,
    the meshed segments' mirror parts by (x_start, x_end)): every variant once per round, in
    order (A B A B), each meshed segment condensed and timed (``interface_segment_stiffness``)."""
    cpu = {variant: {} for variant in variants}
    matrices = {}
    for _ in range(rounds):
        for variant, (interface, meshes) in variants.items():
            condensed = {}
            for key, (segment, starts, ends, labels) in interface_condensations(plan, interface).items():
                start = time.process_time()
                condensed[key] = interface_segment_stiffness(segment, meshes[key[:2]], starts, ends, labels, scale)
                cpu[variant].setdefault(key[:2], []).append(time.process_time() - start)
            matrices[variant] = joined_through_interface(plan, condensed, interface)
        print(f"round done (load {os.getloadavg()[0]:.1f}, peak {peak_gb():.2f} GB)", flush=True)
    return cpu, matrices


def peak_gb() -> float:
    """This process's peak resident memory so far [GB]."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def print_against_untied(matrices: dict, untied: np.ndarray, rows) -> None:
    """A markdown table: each dominant entry of ``rows``, (K - untied) / |untied| [%] per matrix,
    and the largest |.| per matrix."""
    labels = list(matrices)
    relative = {label: {entry: 100 * (matrices[label][entry_index(entry)] - untied[entry_index(entry)])
                        / abs(untied[entry_index(entry)]) for entry, *_ in rows} for label in labels}
    print("| entry | " + " | ".join(labels) + " |")
    print("|---|" + "---:|" * len(labels))
    for entry, *_ in rows:
        print(f"| {entry} | " + " | ".join(f"{relative[label][entry]:+.3f}" for label in labels) + " |")
    print("| largest abs | " + " | ".join(f"{max(abs(v) for v in relative[label].values()):.3f}"
                                          for label in labels) + " |")


if __name__ == "__main__":
    main()
