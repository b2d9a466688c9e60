"""CPU of the FEM segments of a cold ``flexcal truth --scenario table1`` on the prototype's grid
(``PROTOTYPE_CHAIN_OPTIONS``) and on a candidate grid (those options updated by --change):
every distinct segment of the as-built table1 mount (``chain_slices``, first half,
``canonical_segment``) meshed and condensed as the provider does (``segment_stiffness``,
mirror part), one thread, base and candidate alternating in one process (A B A B), so both
see the same load. The segments are ~90 % of a cold table1 truth's CPU (docs/meshing.md,
"Session 20: whole chains").

    python benchmarks/bench_prototype_grid_cost.py --change '{"n_arc": 8}' --rounds 2
    python benchmarks/bench_prototype_grid_cost.py --middle --rounds 2

--middle: the candidate is the prototype's grid (--change still applies) on the halves
[0, L/2] of the as-built chains whose strut is at least ``LONG_STRUT`` section widths long
(the chain cut once, at its middle), and on the whole of the others (not cut: the cut at
the middle of D1's 30 mm strut adds 0.48 % in torsion; docs/meshing.md, "Session 20:
cutting where the ties do not matter"), against today's segments at 7. Each candidate is
meshed at the first of --through and --through + 1 cells asked for whose grid has both
mirror planes (a quarter, condensed 4 times; at 7 a D chain has none: 281k DOF for its half).
"""

from __future__ import annotations

import argparse
import json
import os
import time


# a strut this many section widths long is cut at its middle (L1: 6.5, its middle 3.3 section
# widths from either end, the tie there adds <= 0.05 %); a shorter one is not cut (D1: 0.6)
LONG_STRUT = 2.0


def quarter_through(segment, through: float, options: dict) -> float:
    """The first of ``through``, ``through + 1`` cells asked for at which ``segment``'s grid has
    both mirror planes (``through`` if neither)."""
    from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain_mirror_part

    for n in (through, through + 1.0):
        if len(mapped_mesh_chain_mirror_part(segment, elements_through_thickness=n, **options)[1]) == 2:
            return n
    return through


def main() -> None:
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS
    from flexcal.validation.prototype.fem_provider import canonical_segment
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.segments import chain_slices
    from flexcal.validation.prototype.truth import as_built
    from flexcal.validation.reports.chain_cuts import segment_stiffness

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--change", default="{}", help="JSON, updates PROTOTYPE_CHAIN_OPTIONS")
    parser.add_argument("--middle", action="store_true", help="candidate: the halves [0, L/2] (docstring)")
    parser.add_argument("--through", type=float, default=7.0, help="cells asked for of the candidate")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    scenario = load_scenario("table1")
    mechanism, _, _ = as_built(scenario.space, scenario.values)
    segments = {}
    for chain, start, end in chain_slices(p.chain for p in mechanism.chains):
        segment, _ = canonical_segment(chain, start, end)
        segments[(segment.chain, segment.x_start, segment.x_end)] = segment
    candidate = {**PROTOTYPE_CHAIN_OPTIONS, **json.loads(args.change)}
    halves = {}
    for chain in dict.fromkeys(p.chain for p in mechanism.chains):
        cut = chain.strut_length >= LONG_STRUT * chain.section
        segment, _ = canonical_segment(chain, 0.0, (0.5 if cut else 1.0) * chain.length)
        halves[(segment.chain, segment.x_start, segment.x_end)] = segment
    candidates = halves if args.middle else segments
    throughs = {key: quarter_through(segment, args.through, candidate) if args.middle else args.through
                for key, segment in candidates.items()}
    print("candidate cells asked for:", sorted(set(throughs.values())))
    print(f"{len(segments)} segments; candidate {args.change}, {len(candidates)} segments at {args.through:g} through"
          f"{' (halves [0, L/2] of long-strut chains, whole chains else)' if args.middle else ''}")
    totals = {"base": [], "candidate": []}
    for round_ in range(args.rounds):
        for label, options, parts in (("base", PROTOTYPE_CHAIN_OPTIONS, segments),
                                      ("candidate", candidate, candidates)):
            cpu, wall = time.process_time(), time.perf_counter()
            for key, segment in parts.items():
                through = 7.0 if label == "base" else throughs[key]
                segment_stiffness(segment, through, options)
            totals[label].append(time.process_time() - cpu)
            print(f"{label} round {round_}: {totals[label][-1]:.1f} s CPU, {time.perf_counter() - wall:.1f} s wall "
                  f"(load {os.getloadavg()[0]:.1f})", flush=True)
    print(f"candidate / base CPU: {sum(totals['candidate']) / sum(totals['base']):.3f}")


if __name__ == "__main__":
    main()
