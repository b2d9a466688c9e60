"""The prototype with its chains' cuts tied through section fields (``--provider fem``)
against today's rigid ties (issue 26, docs/meshing.md "Session 24: the tied-cut frame"): per
chain of a scenario's as-built mount, the end block (A clamped) of the frame's chain stiffness
K_chain against that of the rigid segments' K_jj, in % on the diagonal; and, given two truth
runs' curves.csv, the angles' difference (RMS and max per angle, µrad).

    python benchmarks/bench_tied_frame.py --scenario table1 --seed 1
    python benchmarks/bench_tied_frame.py --curves A/curves.csv B/curves.csv

The first builds the tied and the rigid providers' matrices into the FEM cache (FLEXCAL_CACHE_DIR) if they
are missing. Not a test (tests/test_chain_twist_stiffness.py, tests/test_prototype_coupled_frame.py).
"""

from __future__ import annotations

import argparse

import numpy as np

from flexcal.fem.cut_warping import clamped_end_stiffness

NAMES = ("ux", "uy", "uz", "rx", "ry", "rz")


def chain_softening(scenario_name: str, seed: int | None) -> None:
    from flexcal.validation.prototype.mechanism import build_prototype
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import as_built

    scenario = load_scenario(scenario_name, seed=seed)
    mechanism, offsets, drives = as_built(scenario.space, scenario.values)
    transmissions = [(x0, cl, mu, scenario.breakaway_force) for x0, cl, mu in drives]
    prototype = build_prototype(mechanism, transmissions, stiffness_provider("fem", progress=False),
                                mount_offsets=offsets)
    # the rigidly tied segments: the provider fem's (the tied prototype's own K_jj hold the cut
    # fields rigid instead, tied_chains.tied_fem_provider)
    rigid_ties = build_prototype(mechanism, transmissions, stiffness_provider("fem-rigid", progress=False),
                                 mount_offsets=offsets)
    print("chain | " + " | ".join(NAMES) + "   (tied - rigid) / rigid [%], end block with A clamped")
    for c, placement in enumerate(prototype.mechanism.chains):
        lengths = np.diff(prototype.section_x[c])
        rigid = np.zeros((30, 30))
        for s in range(5):
            rigid[6 * s:6 * s + 6, 6 * s:6 * s + 6] = rigid_ties.segment_stiffness[c, s]
        tied = clamped_end_stiffness(prototype.chain_stiffness[c], lengths)
        rigid = clamped_end_stiffness(rigid, lengths)
        print(f"{placement.name} | " + " | ".join(f"{100 * (tied[i, i] / rigid[i, i] - 1):+.2f}" for i in range(6)))


def angle_differences(first: str, second: str) -> None:
    import pandas as pd

    a, b = pd.read_csv(first), pd.read_csv(second)
    for column in ("theta_x_urad", "theta_y_urad", "theta_z_urad"):
        d = b[column].to_numpy() - a[column].to_numpy()
        print(f"{column}: second - first RMS {np.sqrt(np.mean(d ** 2)):.3f}, max {np.abs(d).max():.3f} urad "
              f"(range of the angle {np.ptp(a[column].to_numpy()):.1f} urad)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=None)
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--curves", nargs=2, default=None, metavar="CSV")
    args = parser.parse_args()
    if args.scenario:
        chain_softening(args.scenario, args.seed)
    if args.curves:
        angle_differences(*args.curves)


if __name__ == "__main__":
    main()
