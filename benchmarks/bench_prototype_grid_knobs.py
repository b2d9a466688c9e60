"""Candidate grids for the prototype's segments against the Q2-hex reference limit, one row per
grid: for each of the four leaf segments (L1 and D1, [0, m1] and [m1, s0]) the error of the
torsion K[rx,rx] and the largest error of a dominant entry (``DOMINANT_FRACTION`` on the finest
reference level) in % of |reference limit|, the DOF of one parity class of the mirror part and
the CPU of its condensation (``chain_reference.prototype_stiffness``: the provider's mirrored
condensation at 7 asked for on ``PROTOTYPE_CHAIN_OPTIONS`` updated by each JSON given).

    python benchmarks/bench_prototype_grid_knobs.py --ref-dir D '{}' '{"grading": 1.0}' \\
        '{"slenderness": 6.25, "even_through": true}'

D holds (or gets) the reference levels hex27_<chain>_<index>_r<r>.npy of
``bench_chain_reference.py`` (r = 6 is ~9 GB: copy them from an earlier run). The reference's
limit is that of its finest three levels (--levels per segment as in docs/meshing.md,
"Session 24: the prototype's grid for tied cuts", where the rows are). One thread; not a test
(tests/test_chain_reference.py::test_fine_prototype_grid_within_three_tenths_of_a_percent...).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

SEGMENTS = (("L1", 0), ("L1", 1), ("D1", 0), ("D1", 1))
LEVELS = {("L1", 0): (2, 3, 4, 5, 6), ("L1", 1): (2, 3, 4, 5, 6), ("D1", 0): (2, 3, 4, 5, 6), ("D1", 1): (2, 3, 4, 5)}
NAMES = [f"{s}{node}" for node in "AB" for s in ("ux", "uy", "uz", "rx", "ry", "rz")]


def main() -> None:
    from flexcal.fem.convergence import dominant_entries
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS, mapped_mesh_chain_mirror_part
    from flexcal.validation.reports.chain_reference import prototype_stiffness, reference_stiffness, segment
    from flexcal.validation.reports.fem import DOMINANT_FRACTION
    from flexcal.validation.reports.hinge_reference import _cached, reference_limit

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("changes", nargs="+", help="JSON each, updates PROTOTYPE_CHAIN_OPTIONS")
    parser.add_argument("--ref-dir", default="bench_chain_reference")
    args = parser.parse_args()
    folder = Path(args.ref_dir).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    references = {}
    for chain, index in SEGMENTS:
        part, levels = segment(chain, index), LEVELS[(chain, index)]
        values = np.array([_cached(folder, f"hex27_{chain}_{index}_r{r}", lambda r=r: reference_stiffness(part, r))
                           for r in levels])
        references[(chain, index)] = (reference_limit(levels, values)[1],
                                      dominant_entries(values[-1], DOMINANT_FRACTION))
    print(f"load {os.getloadavg()[0]:.1f}; K[rx,rx] / largest error of a dominant entry [%] (DOF per class, CPU)")
    print("| change | " + " | ".join(f"{c} {('[0, m1]', '[m1, s0]')[i]}" for c, i in SEGMENTS) + " |")
    print("|---|" + "---:|" * len(SEGMENTS))
    for change in args.changes:
        options = {**PROTOTYPE_CHAIN_OPTIONS, **json.loads(change)}
        cells = []
        for chain, index in SEGMENTS:
            part = segment(chain, index)
            limit, mask = references[(chain, index)]
            n_dof = mapped_mesh_chain_mirror_part(part, elements_through_thickness=7, **options)[0].n_dof
            cpu = time.process_time()
            k, _ = prototype_stiffness(part, options)
            cpu = time.process_time() - cpu
            error = np.where(mask, (k - limit) / np.abs(limit), 0.0)
            i, j = np.unravel_index(np.argmax(np.abs(error)), error.shape)
            cells.append(f"{100 * error[3, 3]:+.3f} / {100 * abs(error[i, j]):.3f} K[{NAMES[i]},{NAMES[j]}] "
                         f"({n_dof / 1e3:.1f}k, {cpu:.1f} s)")
        print(f"| {change} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
