"""Convergence of the mapped chain mesher: every dominant stiffness entry of chain segments
(or whole chains) under refinement, its fitted rate and Richardson limit, against fTetWild.

    python benchmarks/bench_chain_convergence.py --chain D1 --segment 0 --levels 4 6 8 --tetwild 3 4 --dir /tmp/conv

--segment k: the prototype's k-th slice (``section_nodes``: 0 = end block, leaf 1, half the
connector; 1 = half the connector, leaf 2, half a section of strut); --segment -1: the whole
chain. Levels: elements through the neck (cell size ~ t / n everywhere in the leaves). Each
12 x 12 stiffness is stored as DIR/<tag>.npy and reused. The table lists every dominant
entry (``DOMINANT_FRACTION`` of ``flexcal.validation.reports.fem``, on the finest matrix):
the finest level, the rate, the Richardson limit, the error of each level against the
limit [%], and the finest fTetWild value with its difference from the limit [%]. Not a test.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

NAMES = ("ux", "uy", "uz", "rx", "ry", "rz")


def _part(chain_name: str, segment: int):
    from flexcal.geometry.params import ChainSegment, reference_mechanism
    from flexcal.validation.prototype.segments import section_nodes

    chain = {c.name: c.chain for c in reference_mechanism().chains}[chain_name]
    if segment < 0:
        return chain
    nodes = section_nodes(chain)
    return ChainSegment(chain=chain, x_start=float(nodes[segment]), x_end=float(nodes[segment + 1]))


def stiffness(part, mesher: str, n: float) -> tuple[np.ndarray, int, float]:
    """(12 x 12 [SI], DOF, wall seconds) of ``part`` meshed by ``mesher`` at n through."""
    from flexcal.fem.condense import chain_stiffness
    from flexcal.geometry.exact import end_planes, reference_points
    from flexcal.geometry.params import STEEL

    start = time.perf_counter()
    if mesher == "mapped":
        from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain

        mesh, _ = mapped_mesh_chain(part, elements_through_thickness=n, measure=False)
    else:
        from flexcal.fem.mesh import mesh_part
        from flexcal.geometry.solids import chain_solid, segment_solid

        solid = segment_solid(part) if hasattr(part, "x_start") else chain_solid(part)
        mesh, _ = mesh_part(solid, elements_through_thickness=n)
    planes, points = end_planes(part), reference_points(part)
    k = chain_stiffness(mesh, STEEL, planes["A"], points["A"], planes["B"], points["B"])
    return 0.5 * (k + k.T), mesh.n_dof, time.perf_counter() - start


def main() -> None:
    from flexcal.fem.convergence import dominant_entries, richardson
    from flexcal.validation.reports.fem import DOMINANT_FRACTION

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chain", default="D1")
    parser.add_argument("--segment", type=int, default=0)
    parser.add_argument("--levels", type=float, nargs=3, default=[4, 6, 8])
    parser.add_argument("--tetwild", type=float, nargs="*", default=[])
    parser.add_argument("--dir", default="bench_chain_convergence")
    args = parser.parse_args()
    folder = Path(args.dir)
    folder.mkdir(parents=True, exist_ok=True)
    os.chdir(folder)  # fTetWild writes its scratch files into the working directory
    part = _part(args.chain, args.segment)
    results = {}
    for mesher, levels in (("mapped", args.levels), ("tetwild", args.tetwild)):
        for n in levels:
            path = Path(f"{mesher}_{args.chain}_{args.segment}_n{n:g}.npy")
            if not path.exists():
                k, dof, wall = stiffness(part, mesher, n)
                np.save(path, k)
                print(f"{mesher} n={n:g}: {dof} DOF, {wall:.1f} s (load {os.getloadavg()[0]:.1f})", flush=True)
            results[(mesher, n)] = np.load(path)
    mapped = np.array([results[("mapped", n)] for n in args.levels])
    fit = richardson(1.0 / np.array(args.levels), mapped)
    mask = np.triu(dominant_entries(mapped[-1], DOMINANT_FRACTION))
    finest_tw = results[("tetwild", args.tetwild[-1])] if args.tetwild else None
    label = [f"{s}{node}" for node in "AB" for s in NAMES]
    print(f"\n{args.chain} segment {args.segment}, mapped levels {args.levels}, fTetWild {args.tetwild}")
    head = " | ".join(f"err n={n:g} [%]" for n in args.levels)
    print(f"| entry | rate | Richardson limit | {head} | fTetWild n={args.tetwild[-1] if args.tetwild else '-'} "
          f"| fTetWild - limit [%] |")
    worst = np.zeros(3)
    for i, j in zip(*np.nonzero(mask)):
        limit = fit.limit[i, j]
        errors = 100.0 * (mapped[:, i, j] - limit) / abs(limit)
        worst = np.maximum(worst, np.abs(errors))
        tw = "" if finest_tw is None else f"{finest_tw[i, j]:.6g} | {100 * (finest_tw[i, j] - limit) / abs(limit):+.3f}"
        print(f"| K[{label[i]},{label[j]}] | {fit.rate[i, j]:.2f} | {limit:.6g} | "
              + " | ".join(f"{e:+.3f}" for e in errors) + f" | {tw} |")
    print("largest |error| of a dominant entry per level [%]: "
          + ", ".join(f"n={n:g}: {w:.3f}" for n, w in zip(args.levels, worst)))


if __name__ == "__main__":
    main()
