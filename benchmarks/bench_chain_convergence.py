"""Convergence of the mapped chain mesher: every dominant stiffness entry of chain segments
(or whole chains) under refinement, its fitted rate and Richardson limit, against fTetWild,
and the error of the default mesh.

    python benchmarks/bench_chain_convergence.py --chain L1 --segment 0 --nested 2 --levels 2 3 4 \\
        --tetwild 3 4 --default --dir /tmp/conv

--segment k: the prototype's k-th slice (``section_nodes``: 0 = end block, leaf 1, half the
connector; 1 = half the connector, leaf 2, half a section of strut); --segment -1: the whole
chain. Levels: elements through the neck n (cell size ~ t / n everywhere in the leaves,
h = 1 / n), or with --nested N the refinement factors r of the grid at N through (every
cell split into r^3: nested meshes, h = 1 / r exactly; the clean sequence). --options: a
JSON dict of ``mapped_mesh_chain`` options for the levels (default: its defaults).
--default: also the default mesh (``mapped_mesh_chain`` as the segment provider calls it)
and its error against the limit. Each 12 x 12 stiffness is stored as DIR/<tag>.npy and
reused. The table lists every dominant entry (``DOMINANT_FRACTION`` of
``flexcal.validation.reports.fem``, on the finest matrix): the rate, the Richardson limit,
the error of each level against the limit [%], the fTetWild reference (its finest two
levels extrapolated at the mapped rate; +- the spread of rates p -+ 1) and its difference
from the limit [%], and the default mesh's error [%]. Not a test.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

NAMES = ("ux", "uy", "uz", "rx", "ry", "rz")


def _part(chain_name: str, segment: int):
    from flexcal.geometry.params import reference_mechanism
    from flexcal.validation.reports.chain_reference import segment as chain_segment

    if segment < 0:
        return {c.name: c.chain for c in reference_mechanism().chains}[chain_name]
    return chain_segment(chain_name, segment)


def stiffness(part, mesher: str, n: float, refinement: int = 1, options: dict | None = None
              ) -> tuple[np.ndarray, int, float]:
    """(12 x 12 [SI], DOF, wall seconds) of ``part`` meshed by ``mesher`` at n through
    (mapped: every cell split into refinement^3, ``options`` to ``mapped_mesh_chain``)."""
    from flexcal.fem.condense import chain_stiffness
    from flexcal.geometry.exact import end_planes, reference_points
    from flexcal.geometry.params import STEEL

    start = time.perf_counter()
    if mesher == "mapped":
        from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain

        mesh, _ = mapped_mesh_chain(part, elements_through_thickness=n, refinement=refinement, measure=False,
                                    **(options or {}))
    else:
        from flexcal.fem.mesh import mesh_part
        from flexcal.geometry.solids import chain_solid, segment_solid

        solid = segment_solid(part) if hasattr(part, "x_start") else chain_solid(part)
        mesh, _ = mesh_part(solid, elements_through_thickness=n)
    planes, points = end_planes(part), reference_points(part)
    k = chain_stiffness(mesh, STEEL, planes["A"], points["A"], planes["B"], points["B"])
    return 0.5 * (k + k.T), mesh.n_dof, time.perf_counter() - start


def two_level_limit(h: tuple[float, float], values: np.ndarray, rate) -> np.ndarray:
    """Richardson limit from two levels (2, ...) at cell sizes h (coarse, fine) and a given
    rate (...) [-]: fine + (fine - coarse) / ((h0 / h1)^p - 1)."""
    ratio = (h[0] / h[1]) ** np.asarray(rate, float)
    return values[1] + (values[1] - values[0]) / (ratio - 1.0)


def _cached(folder: Path, tag: str, compute) -> np.ndarray:
    path = folder / f"{tag}.npy"
    if not path.exists():
        k, dof, wall = compute()
        np.save(path, k)
        print(f"{tag}: {dof} DOF, {wall:.1f} s (load {os.getloadavg()[0]:.1f})", flush=True)
    return np.load(path)


def main() -> None:
    from flexcal.fem.convergence import dominant_entries, richardson
    from flexcal.validation.reports.fem import DOMINANT_FRACTION

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chain", default="D1")
    parser.add_argument("--segment", type=int, default=0)
    parser.add_argument("--levels", type=float, nargs=3, default=[4, 6, 8])
    parser.add_argument("--nested", type=float, default=None)
    parser.add_argument("--options", default="{}")
    parser.add_argument("--tetwild", type=float, nargs="*", default=[])
    parser.add_argument("--default", action="store_true")
    parser.add_argument("--dir", default="bench_chain_convergence")
    args = parser.parse_args()
    options = json.loads(args.options)
    folder = Path(args.dir).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    os.chdir(folder)  # fTetWild writes its scratch files into the working directory
    part = _part(args.chain, args.segment)
    stem = f"{args.chain}_{args.segment}"
    suffix = "".join(f"_{k}{v}" for k, v in sorted(options.items()))
    mapped = []
    for level in args.levels:
        if args.nested:
            tag = f"mapped_{stem}_n{args.nested:g}_r{level:g}{suffix}"
            mapped.append(_cached(folder, tag, lambda: stiffness(part, "mapped", args.nested, int(level), options)))
        else:
            tag = f"mapped_{stem}_n{level:g}{suffix}"
            mapped.append(_cached(folder, tag, lambda: stiffness(part, "mapped", level, 1, options)))
    mapped = np.array(mapped)
    tetwild = np.array([_cached(folder, f"tetwild_{stem}_n{n:g}", lambda: stiffness(part, "tetwild", n))
                        for n in args.tetwild])
    if args.default:
        from flexcal.validation.prototype.fem_provider import DEFAULT_ELEMENTS_THROUGH

        default = _cached(folder, f"default{DEFAULT_ELEMENTS_THROUGH:g}_{stem}",
                          lambda: stiffness(part, "mapped", DEFAULT_ELEMENTS_THROUGH))
    else:
        default = None
    fit = richardson(1.0 / np.array(args.levels), mapped)
    mask = np.triu(dominant_entries(mapped[-1], DOMINANT_FRACTION))
    reference = spread = None
    if len(args.tetwild) >= 2:
        h = (1.0 / args.tetwild[-2], 1.0 / args.tetwild[-1])
        reference = two_level_limit(h, tetwild[-2:], fit.rate)
        low = two_level_limit(h, tetwild[-2:], np.maximum(fit.rate - 1.0, 0.5))
        high = two_level_limit(h, tetwild[-2:], fit.rate + 1.0)
        spread = 0.5 * np.abs(low - high)
    label = [f"{s}{node}" for node in "AB" for s in NAMES]
    kind = f"nested at n = {args.nested:g}, r" if args.nested else "n"
    print(f"\n{args.chain} segment {args.segment}, mapped {kind} = {args.levels} {options or ''}, "
          f"fTetWild n = {args.tetwild}")
    head = " | ".join(f"{kind.split(',')[-1].strip()} = {n:g} [%]" for n in args.levels)
    print(f"| entry | rate | Richardson limit | {head} | fTetWild reference - limit [%] | default [%] |")
    worst = np.zeros(len(args.levels) + 1)
    for i, j in zip(*np.nonzero(mask)):
        limit = fit.limit[i, j]
        errors = 100.0 * (mapped[:, i, j] - limit) / abs(limit)
        ref = "" if reference is None else \
            f"{100 * (reference[i, j] - limit) / abs(limit):+.3f} +- {100 * spread[i, j] / abs(limit):.3f}"
        err_default = np.nan if default is None else 100.0 * (default[i, j] - limit) / abs(limit)
        worst = np.fmax(worst, np.abs(np.append(errors, err_default)))
        print(f"| K[{label[i]},{label[j]}] | {fit.rate[i, j]:.2f} | {limit:.6g} | "
              + " | ".join(f"{e:+.3f}" for e in errors) + f" | {ref} | {err_default:+.3f} |")
    print("largest |error| of a dominant entry [%]: "
          + ", ".join(f"level {n:g}: {w:.3f}" for n, w in zip(args.levels, worst))
          + (f", default: {worst[-1]:.3f}" if default is not None else ""))


if __name__ == "__main__":
    main()
