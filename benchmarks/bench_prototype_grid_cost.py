"""CPU of the FEM segments of a cold ``flexcal truth --scenario table1`` on the prototype's grid
(``PROTOTYPE_CHAIN_OPTIONS``) and on a candidate grid (those options updated by --change):
every distinct segment of the as-built table1 mount (``chain_slices``, first half,
``canonical_segment``) meshed and condensed as the provider does (``segment_stiffness``,
mirror part), one thread, base and candidate alternating in one process (A B A B), so both
see the same load. The segments are ~90 % of a cold table1 truth's CPU (docs/meshing.md,
"Session 20: whole chains").

    python benchmarks/bench_prototype_grid_cost.py --change '{"n_arc": 8}' --rounds 2
"""

from __future__ import annotations

import argparse
import json
import os
import time


def main() -> None:
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS
    from flexcal.validation.prototype.fem_provider import canonical_segment
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.segments import chain_slices
    from flexcal.validation.prototype.truth import as_built
    from flexcal.validation.reports.chain_cuts import segment_stiffness

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--change", required=True, help="JSON, updates PROTOTYPE_CHAIN_OPTIONS")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    scenario = load_scenario("table1")
    mechanism, _, _ = as_built(scenario.space, scenario.values)
    segments = {}
    for chain, start, end in chain_slices(p.chain for p in mechanism.chains):
        segment, _ = canonical_segment(chain, start, end)
        segments[(segment.chain, segment.x_start, segment.x_end)] = segment
    candidate = {**PROTOTYPE_CHAIN_OPTIONS, **json.loads(args.change)}
    print(f"{len(segments)} segments; candidate {args.change}")
    totals = {"base": [], "candidate": []}
    for round_ in range(args.rounds):
        for label, options in (("base", PROTOTYPE_CHAIN_OPTIONS), ("candidate", candidate)):
            cpu, wall = time.process_time(), time.perf_counter()
            for segment in segments.values():
                segment_stiffness(segment, 7.0, options)
            totals[label].append(time.process_time() - cpu)
            print(f"{label} round {round_}: {totals[label][-1]:.1f} s CPU, {time.perf_counter() - wall:.1f} s wall "
                  f"(load {os.getloadavg()[0]:.1f})", flush=True)
    print(f"candidate / base CPU: {sum(totals['candidate']) / sum(totals['base']):.3f}")


if __name__ == "__main__":
    main()
