"""The two-stage measurement of docs/calibration.md 9, end to end on the FEM prototype (issues #24, #28).

    .venv/bin/python benchmarks/bench_two_stage.py --out runs/two-stage/s1 --seed 1 \
        [--scenario paper] [--model consistent] [--noise-urad 0.5] [--candidates 2000] \
        [--keep-standard K] [--region workspace|box|hull] [--combined] [--combined-candidates 500] [--redo]

Stages (each one's output folder under --out; a stage whose result is already there is reused
unless --redo, so a run cut short resumes):

1. ``std``: ``flexcal verify --scenario S --seed N --noise-urad 0.5 --model M`` on the standard
   trajectory, then the held-out walk (``bench_design_heldout``: the model at the estimate
   against the noise-free prototype of the same seed along ``bench_form_error.random_walk``,
   77 postures, stroke 1.0, seed 28).
2. ``design``: ``flexcal design --scenario S --at std/report.json --model M --inadequacy none
   --candidates C`` (the D-optimal design at the identified values, where the drives' nuts
   are in their gaps). With ``--keep-standard K`` (and/or ``--region R``) the design keeps
   the K-point standard trajectory first and designs the other 77 - K postures: stage folders
   ``design-kK[-R]`` / ``designed-kK[-R]`` and OUT/two_stage-kK[-R].json, so variants share one
   stage 1 (and may run side by side).
3. ``designed``: stage 1's verify and held-out walk on the designed trajectory (the same seed:
   the same prototype and the same noise stream).
4. with --combined: ``design-combined`` (``--points 154 --keep-standard 77 --candidates
   C2``: the standard trajectory followed by 77 designed postures, one measurement) and
   ``combined`` (its verify and held-out walk).

Writes OUT/two_stage.json (every stage's Table 1 drive rows, sources alone, z, fit/noise, the
model-form floor, held-out RMS, wall times) and prints a Markdown table of it. Not a test (a
consistent verify on the FEM prototype takes minutes); the figures go into
docs/calibration.md ("The `paper` Table 1 by a two-stage measurement").
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import bench_design_heldout  # noqa: E402

PAPER = {"x0": 2.7, "CL": 0.02, "mu": 1.3}  # Table 1 of the paper: um, mm, % (relative)


def _verify(out: Path, args, trajectory: Path | None, redo: bool) -> dict:
    done = out / "heldout.json"
    if not done.exists() or redo:
        argv = ["--out", str(out), "--seed", str(args.seed), "--scenario", args.scenario, "--model", args.model,
                "--noise-urad", str(args.noise_urad), "--walk-seed", str(args.walk_seed)]
        if trajectory is not None:
            argv += ["--trajectory", str(trajectory)]
        started = time.perf_counter()
        bench_design_heldout.main(argv)
        heldout = json.loads(done.read_text())
        heldout["stage_wall_s"] = time.perf_counter() - started
        done.write_text(json.dumps(heldout, indent=1))
    heldout = json.loads(done.read_text())
    report = json.loads((out / "report.json").read_text())
    # from report.json, so a stage made before these fields existed still summarizes
    heldout["drives"] = bench_design_heldout.drive_rows(report)
    heldout["form_floor"] = bench_design_heldout.form_floor(report)
    heldout["fit_over_noise"] = report.get("fit_rms_over_noise_floor")
    z_alone = [d["z"] for d in heldout["drives"].values() if d["alone"] and d["z"] is not None]
    heldout["z_rms_drives_alone"] = (sum(z * z for z in z_alone) / len(z_alone)) ** 0.5 if z_alone else None
    return heldout


def _design(out: Path, args, report: Path, extra: list[str], redo: bool) -> dict:
    done = out / "report.json"
    if not done.exists() or redo:
        from flexcal.validation.cli import main as main_cli

        argv = ["design", "--scenario", args.scenario, "--at", str(report), "--model", args.model,
                "--inadequacy", "none", "--noise-urad", str(args.noise_urad), "--out", str(out), "--force", *extra]
        started = time.perf_counter()
        status = main_cli(argv)
        if status != 0:
            raise SystemExit(f"flexcal design failed (status {status}): {' '.join(argv)}")
        (out / "wall.json").write_text(json.dumps({"wall_s": time.perf_counter() - started, "argv": argv}))
    design = json.loads(done.read_text())
    wall = json.loads((out / "wall.json").read_text()) if (out / "wall.json").exists() else {}
    keep = ("log_det_information", "rank", "n_sources_below_1pct")
    return {"wall_s": wall.get("wall_s"), "argv": wall.get("argv"), "n_points": design.get("n_points"),
            "n_candidates": design.get("n_candidates"), "design_point": design.get("design_point"),
            "designed": {k: design["designed"][k] for k in keep},
            "standard_trajectory": {k: design["standard_trajectory"][k] for k in keep}}


def _beats(a: dict, b: dict) -> dict:
    """Issue #28's test of trajectory a against b: the largest x0/CL/mu error over the drive
    sources both identify alone (each in Table 1's unit over the paper's figure, so one scale),
    how many each identifies alone, the held-out RMS."""
    both = [n for n in a["drives"] if a["drives"][n]["alone"] and b["drives"][n]["alone"]]

    def worst(run):
        return max((run["drives"][n]["error"] / PAPER[n.split(".")[1]] for n in both), default=float("nan"))

    out = {"both_alone": both, "worst_over_paper": [worst(a), worst(b)],
           "n_alone": [len(a["alone"]), len(b["alone"])], "heldout_rms_urad": [a["heldout_rms_urad"], b["heldout_rms_urad"]]}
    out["beats"] = bool(worst(a) < worst(b) and len(a["alone"]) >= len(b["alone"])
                        and a["heldout_rms_urad"] < b["heldout_rms_urad"])
    return out


def _row(name: str, run: dict) -> str:
    def cell(kind):
        parts = []
        for i in (1, 2, 3):
            d = run["drives"][f"D{i}.{kind}"]
            text = f"{d['error']:.3g}" if kind != "CL" else f"{d['error']:.2g}"
            parts.append(text if d["alone"] else text + "*")
        return " / ".join(parts)

    floor = run["form_floor"].get("run", {})
    rms = floor.get("rms_urad") or {}
    floor_text = "/".join(f"{v:.2g}" for v in rms.values()) + f" (max {floor.get('max_urad', float('nan')):.2g})" if rms else "-"
    z = ", ".join(f"{n} {d['z']:.2f}" for n, d in run["drives"].items() if d["alone"] and d["z"] is not None)
    return (f"| {name} | {run['n_points']} | {len(run['alone'])}: {', '.join(run['alone'])} | {cell('x0')} | {cell('CL')} "
            f"| {cell('mu')} | {z} | {run['fit_over_noise']:.2f} | {floor_text} | {run['heldout_rms_urad']:.3f} "
            f"(floor {run['heldout_floor_urad']:.3f}) | {run.get('verify_wall_s') or float('nan'):.0f} |")


def _variant(args) -> str:
    """The designed stage's folder suffix: "" for the plain design, "-kK[-region]" otherwise."""
    if args.keep_standard == 0 and args.region == "workspace":
        return ""
    return f"-k{args.keep_standard}" + ("" if args.region == "workspace" else f"-{args.region}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True)
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--scenario", default="paper")
    parser.add_argument("--model", default="consistent")
    parser.add_argument("--noise-urad", type=float, default=0.5)
    parser.add_argument("--walk-seed", type=int, default=28)
    parser.add_argument("--candidates", type=int, default=2000, help="candidates of the designed-alone stage")
    parser.add_argument("--keep-standard", type=int, default=0, metavar="K",
                        help="the designed stage keeps the K-point standard trajectory first and designs 77 - K")
    parser.add_argument("--region", default="workspace", choices=("workspace", "box", "hull"),
                        help="where the designed stage's candidates are drawn (flexcal design --region)")
    parser.add_argument("--combined", action="store_true",
                        help="also the standard trajectory followed by 77 designed postures (one measurement)")
    parser.add_argument("--combined-candidates", type=int, default=500)
    parser.add_argument("--skip-designed", action="store_true", help="only the standard and the combined stages")
    parser.add_argument("--redo", action="store_true", help="rerun stages whose results are already in --out")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    threads = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}

    summary = {"scenario": args.scenario, "seed": args.seed, "model": args.model, "noise_urad": args.noise_urad,
               "threads": threads, "paper": PAPER, "runs": {}, "designs": {}}
    summary["runs"]["standard"] = _verify(out / "std", args, None, args.redo)
    variant = _variant(args)
    if not args.skip_designed:
        extra = ["--candidates", str(args.candidates), "--keep-standard", str(args.keep_standard),
                 "--region", args.region]
        name = f"designed{variant}"
        summary["designs"][name] = _design(out / f"design{variant}", args, out / "std" / "report.json", extra,
                                           args.redo)
        summary["runs"][name] = _verify(out / name, args, out / f"design{variant}" / "trajectory.csv", args.redo)
    if args.combined:
        summary["designs"]["combined"] = _design(out / "design-combined", args, out / "std" / "report.json",
                                                 ["--points", "154", "--keep-standard", "77", "--candidates",
                                                  str(args.combined_candidates)], args.redo)
        summary["runs"]["combined"] = _verify(out / "combined", args, out / "design-combined" / "trajectory.csv",
                                              args.redo)
    for name, run in summary["runs"].items():
        if name != "standard":
            summary[f"{name}_vs_standard"] = _beats(run, summary["runs"]["standard"])
    (out / f"two_stage{variant}.json").write_text(json.dumps(summary, indent=1))

    print(f"{args.scenario} seed {args.seed}, --model {args.model}, {args.noise_urad} urad; errors x0 um, CL mm, mu % "
          "(relative); *: not identified alone")
    print("| trajectory | points | alone | x0 D1/D2/D3 | CL D1/D2/D3 | mu D1/D2/D3 | z (alone) | fit/noise "
          "| floor RMS x/y/z urad | held-out RMS urad | verify wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, run in summary["runs"].items():
        print(_row(name, run))
    for key in summary:
        if key.endswith("_vs_standard"):
            print(key, json.dumps(summary[key]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
