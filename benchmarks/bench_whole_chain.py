"""The whole L1 and D1 chains' 12 x 12 (issue 26, whole chains): every dominant entry of the
prototype's chain (its five segments composed) against an estimate of the converged
stiffness of the chain in one piece (``converged_chain_estimate``): the converged tied
segments joined (the Q2-hex reference limits of [0, m1] and [m1, s0], ``bench_chain_reference.py``,
and the Richardson limit of the strut segment refined r = 4, 5, 6), less what the rigid ties at
the four cuts add (tied - untied of the one-piece chain mesh, ``bench_chain_cuts.py``).

    python benchmarks/bench_whole_chain.py --chain L1 --ref-dir D --cuts-dir C \\
        --ref-levels 2 3 4 5 6 --ref-levels-2 3 4 5 6
    python benchmarks/bench_whole_chain.py --chain D1 --through 8 --ref-dir D --cuts-dir C \\
        --ref-levels 2 3 4 5 6 --ref-levels-2 2 3 4 5
    python benchmarks/bench_whole_chain.py --chain D1 --through 8 --middle-through 8 ...  # + the cut at L/2
    python benchmarks/bench_whole_chain.py --chain L1 ... --segment-options JSON  # P on a candidate grid

The reference levels are read from D/hex27_<chain>_<0|1>_r<r>.npy (computed and stored if
missing: r = 6 is ~9 GB); the one-piece matrices from C (bench_chain_cuts.py's, computed if
missing). P - C = (P - S) + (T - U): the segments' discretisation (P the prototype's
segments joined, S the converged tied segments joined) and the ties (T, U the one-piece
mesh tied and untied). One OMP/MKL thread; docs/meshing.md ("Session 20: whole chains").
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench_chain_cuts import cut_tag
from flexcal.fem.convergence import richardson
from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS
from flexcal.validation.prototype.segments import end_stiffness, expand_end_stiffness, section_nodes
from flexcal.validation.reports.chain_cuts import (chain_segments, converged_chain_estimate, cut_rows, entry_index,
                                                   one_piece_stiffness, segment_stiffness, series_stiffness, stretch)
from flexcal.validation.reports.chain_reference import reference_chain, reference_stiffness, segment
from flexcal.validation.reports.hinge_reference import _cached, reference_limit


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chain", nargs="+", default=["L1"])
    parser.add_argument("--through", type=float, default=7.0, help="cells asked for of the one-piece mesh")
    parser.add_argument("--options", default="{}", help="JSON, updates PROTOTYPE_CHAIN_OPTIONS (one-piece mesh)")
    parser.add_argument("--segment-options", default="{}",
                        help="JSON, updates PROTOTYPE_CHAIN_OPTIONS for the prototype's segments P (a "
                             "candidate grid; the strut's limit stays that of today's grid refined)")
    parser.add_argument("--ref-levels", type=int, nargs="+", default=[2, 3, 4, 5, 6], help="[0, m1]")
    parser.add_argument("--ref-levels-2", type=int, nargs="+", default=[3, 4, 5, 6], help="[m1, s0]")
    parser.add_argument("--strut-levels", type=int, nargs=3, default=[4, 5, 6])
    parser.add_argument("--middle-through", type=float, default=None,
                        help="also the chain cut once, at its middle: its halves at this many cells asked for "
                             "joined (P'), the tie at L/2 (T' - U'), and the chain in one piece (U'), from "
                             "bench_chain_cuts.py --middle's matrices in --cuts-dir")
    parser.add_argument("--strut-depth", type=float, default=None,
                        help="[mm] with --middle-through: the chain cut in its strut this far from either end "
                             "instead of at L/2 (bench_chain_cuts.py --strut-depth)")
    parser.add_argument("--ref-dir", default="bench_chain_reference")
    parser.add_argument("--cuts-dir", default="bench_chain_cuts")
    args = parser.parse_args()
    ref_dir, cuts_dir = Path(args.ref_dir).resolve(), Path(args.cuts_dir).resolve()
    ref_dir.mkdir(parents=True, exist_ok=True)
    cuts_dir.mkdir(parents=True, exist_ok=True)
    change = json.loads(args.options)
    for name in args.chain:
        estimate = whole_chain_estimate(name, args.through, change, ref_dir, cuts_dir, args.ref_levels,
                                        args.ref_levels_2, args.strut_levels,
                                        segment_change=json.loads(args.segment_options))
        converged, untied, tied, prototype, joined, strut_part, strut_fit, uncertainty, limits = (
            estimate[k] for k in ("converged", "untied", "tied", "prototype", "joined", "strut_part", "strut_fit",
                                  "uncertainty", "limits"))
        print(f"\n{name} whole chain: prototype P (its segments joined) against the estimate C (converged tied "
              f"segments joined, S, less the ties' part T - U at {args.through:g} asked for)")
        print(f"strut segment rates {np.nanmin(np.diag(strut_fit.rate)):.2f}-{np.nanmax(np.diag(strut_fit.rate)):.2f}; "
              "reference uncertainty of the diagonal <= "
              f"{100 * max(np.max(np.diag(uncertainty[i]) / np.abs(np.diag(limits[i]))) for i in (0, 1)):.3f} %")
        middle = None
        if args.middle_through is not None:
            label = "mid" if args.strut_depth is None else f"strut{args.strut_depth:g}"
            mid_tag = cut_tag(name, label, args.middle_through, change)
            middle = {kind: np.load(cuts_dir / f"{kind}_{mid_tag}.npy") for kind in ("composed", "tied", "untied")}
        where = "L/2" if args.strut_depth is None else f"{args.strut_depth:g} mm into the strut"
        extra = ((f" cut at {where}: P' - C [%] | its ties: T' - U' [%] | no cut: U' - C [%] |", "---:|---:|---:|")
                 if middle else ("", ""))
        print("| entry | prototype P | estimate C | P - C [%] | segments P - S [%] | of which strut [%] | "
              f"ties T - U [%] |{extra[0]}")
        print(f"|---|---:|---:|---:|---:|---:|---:|{extra[1]}")
        for entry, *_ in cut_rows(prototype, tied, untied):
            i, j = entry_index(entry)
            scale = abs(converged[i, j])
            tail = (f" {100 * (middle['composed'][i, j] - converged[i, j]) / scale:+.3f} | "
                    f"{100 * (middle['tied'][i, j] - middle['untied'][i, j]) / abs(middle['untied'][i, j]):+.3f} | "
                    f"{100 * (middle['untied'][i, j] - converged[i, j]) / scale:+.3f} |"
                    if middle else "")
            print(f"| {entry} | {prototype[i, j]:.6e} | {converged[i, j]:.6e} | "
                  f"{100 * (prototype[i, j] - converged[i, j]) / scale:+.3f} | "
                  f"{100 * (prototype[i, j] - joined[i, j]) / scale:+.3f} | {100 * strut_part[i, j] / scale:+.3f} | "
                  f"{100 * (tied[i, j] - untied[i, j]) / scale:+.3f} |{tail}")


def whole_chain_estimate(name: str, through: float, change: dict, ref_dir: Path, cuts_dir: Path, ref_levels,
                         ref_levels_2, strut_levels, segment_change: dict | None = None) -> dict:
    """The whole chain ``name``'s estimate C = S - (T - U) and its parts (module docstring):
    {"converged": C, "untied": U, "tied": T (the one piece at ``through`` asked for, options
    changed by ``change``), "prototype": P, "joined": S, "strut_part", "strut_fit",
    "uncertainty" and "limits" of the two leaf segments' reference levels} (12 x 12 [SI]);
    ``segment_change``: P's segments on the prototype's options changed by it (a candidate grid)."""
    chain = reference_chain(name)
    limits, uncertainty = {}, {}
    for index, levels in ((0, ref_levels), (1, ref_levels_2)):
        part = segment(name, index)
        values = np.array([_cached(ref_dir, f"hex27_{name}_{index}_r{r}", lambda r=r: reference_stiffness(part, r))
                           for r in levels])
        _, limits[index], uncertainty[index], _ = reference_limit(levels, values)
    strut = [_cached(cuts_dir, f"strut_{name}_r{r}",
                     lambda r=r: (segment_stiffness(segment(name, 2), 7.0, PROTOTYPE_CHAIN_OPTIONS, r), -1))
             for r in strut_levels]
    strut_fit = richardson(1.0 / np.asarray(strut_levels, float), np.array(strut))
    # an entrywise limit need not keep the six rigid motions in the null space, and a short
    # stiff segment (D1's 15 mm strut) joined in series turns that defect into large errors:
    # each limit is rebuilt from its end block K_BB (A clamped), which defines it
    lengths = np.diff(section_nodes(chain))
    by_start = {i: expand_end_stiffness(end_stiffness(k), float(lengths[i]))
                for i, k in enumerate((limits[0], limits[1], strut_fit.limit))}
    starts = {round(float(x), 12): i for i, x in enumerate(section_nodes(chain)[:3])}
    converged_segments = chain_segments(chain, 5, lambda seg: by_start[starts[round(seg.x_start, 12)]])
    tag = cut_tag(name, 5, through, change)
    paths = {kind: cuts_dir / f"{kind}_{tag}.npy" for kind in ("untied", "tied")}
    if not all(p.exists() for p in paths.values()):
        whole, cuts = stretch(chain, 5)
        untied, (tied,), _ = one_piece_stiffness(whole, cuts, through, {**PROTOTYPE_CHAIN_OPTIONS, **change})
        np.save(paths["untied"], untied)
        np.save(paths["tied"], tied)
    untied, tied = np.load(paths["untied"]), np.load(paths["tied"])
    segment_options = {**PROTOTYPE_CHAIN_OPTIONS, **(segment_change or {})}
    prototype_segments = chain_segments(chain, 5, lambda seg: segment_stiffness(seg, 7.0, segment_options))
    prototype = series_stiffness(prototype_segments)
    strut_converged = prototype_segments.copy()
    strut_converged[2] = by_start[2]
    return {"converged": converged_chain_estimate(converged_segments, tied, untied), "untied": untied, "tied": tied,
            "prototype": prototype, "joined": series_stiffness(converged_segments),
            "strut_part": prototype - series_stiffness(strut_converged), "strut_fit": strut_fit,
            "uncertainty": uncertainty, "limits": limits}


if __name__ == "__main__":
    main()
