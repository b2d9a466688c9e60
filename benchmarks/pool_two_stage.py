"""Issue #28's design test per mount: pool ``bench_two_stage.py`` runs over their seeds.

    .venv/bin/python benchmarks/pool_two_stage.py runs/two-stage/table1-s1 runs/two-stage/table1-s2 ... \
        [--summary two_stage-k41-drives-quadratic-start.json] [--designed designed-k41-drives]

For each mount (the summaries' ``scenario``) and each trajectory (the standard and the designed
stage named by --designed): the largest error over the drive sources both identify alone in
units of its paper figure (``bench_two_stage._beats``' ``worst_over_paper``) per seed and its
RMS over the seeds, the sources identified alone summed over the seeds, the held-out RMS per
seed and its RMS over the seeds, and the z RMS of the sources alone and of the base parameters
pooled over the seeds (root of the n-weighted mean square). The designed trajectory beats the
standard one on a mount when its pooled largest error and held-out RMS are lower and its
sources alone at least as many (docs/calibration.md 11, session 20).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path


def rms(values: list[float]) -> float:
    return math.sqrt(sum(v * v for v in values) / len(values))


def pooled_z(runs: list[dict], key: str, count: str) -> tuple[float, int]:
    """(z RMS over every value of every run, number of values) from each run's RMS and count."""
    n = sum(r[count] for r in runs)
    return math.sqrt(sum(r[count] * r[key] ** 2 for r in runs) / n), n


def pool(summaries: list[dict], designed: str) -> dict[str, dict]:
    """Per mount: {"seeds", "standard": {...}, designed: {...}, "beats": bool} (module docstring)."""
    mounts: dict[str, list[dict]] = {}
    for summary in summaries:
        mounts.setdefault(summary["scenario"], []).append(summary)
    out = {}
    for mount, runs in mounts.items():
        runs = sorted(runs, key=lambda s: s["seed"])
        tests = [s[f"{designed}_vs_standard"] for s in runs]
        entry = {"seeds": [s["seed"] for s in runs]}
        for index, name in ((0, designed), (1, "standard")):  # _beats(a = designed, b = standard)
            stages = [s["runs"][name] for s in runs]
            worst = [t["worst_over_paper"][index] for t in tests]
            held = [t["heldout_rms_urad"][index] for t in tests]
            entry[name] = {"worst_over_paper": worst, "worst_rms": rms(worst),
                           "alone": sum(t["n_alone"][index] for t in tests),
                           "heldout_urad": held, "heldout_rms": rms(held),
                           "z_alone": pooled_z(stages, "z_rms_pure", "n_pure"),
                           "z_base": pooled_z(stages, "z_rms_base", "n_base")}
        a, b = entry[designed], entry["standard"]
        entry["beats"] = bool(a["worst_rms"] < b["worst_rms"] and a["alone"] >= b["alone"]
                              and a["heldout_rms"] < b["heldout_rms"])
        out[mount] = entry
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", help="bench_two_stage.py --out folders (one seed each)")
    parser.add_argument("--summary", default="two_stage-k41-drives-quadratic-start.json")
    parser.add_argument("--designed", default="designed-k41-drives", help="the designed stage's name in the summary")
    args = parser.parse_args()
    summaries = [json.loads((Path(f) / args.summary).read_text()) for f in args.folders]
    for mount, entry in pool(summaries, args.designed).items():
        print(f"{mount}, seeds {entry['seeds']}: designed beats standard per mount: {entry['beats']}")
        for name in ("standard", args.designed):
            e = entry[name]
            print(f"  {name}: largest / paper {' / '.join(f'{v:.3f}' for v in e['worst_over_paper'])} "
                  f"(RMS {e['worst_rms']:.3f}); alone {e['alone']}; held-out "
                  f"{' / '.join(f'{v:.3f}' for v in e['heldout_urad'])} (RMS {e['heldout_rms']:.3f}) urad; "
                  f"z RMS alone {e['z_alone'][0]:.2f} ({e['z_alone'][1]}), base {e['z_base'][0]:.2f} ({e['z_base'][1]})")


if __name__ == "__main__":
    main()
