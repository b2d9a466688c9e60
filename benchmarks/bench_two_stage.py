"""The two-stage measurement of docs/calibration.md 9, end to end on the FEM prototype (issues #24, #28).

    .venv/bin/python benchmarks/bench_two_stage.py --out runs/two-stage/s1 --seed 1 \
        [--scenario paper] [--model consistent] [--noise-urad 0.5] [--candidates 2000] \
        [--keep-standard K] [--region workspace|box|hull] [--combined] [--combined-candidates 500] \
        [--dimension-terms linear|quadratic] [--criterion D|I|drives] [--no-start] [--redo]

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
   stage 1 (and may run side by side). ``--criterion C`` goes to the design (``flexcal design
   --criterion``; "drives": A-optimal on the drive sources' bars over their paper figures); when
   not D it names the designed stages too (``design-k41-drives``, ``designed-k41-drives``).
3. ``designed``: stage 1's verify and held-out walk on the designed trajectory (the same seed:
   the same prototype and the same noise stream).
4. with --combined: ``design-combined`` (``--points 154 --keep-standard 77 --candidates
   C2``: the standard trajectory followed by 77 designed postures, one measurement) and
   ``combined`` (its verify and held-out walk).

The designed verifies (3, 4) start every fit at stage 1's estimate (``flexcal verify --start
std/report.json``: from the prior mean a fit on a designed trajectory's large strokes can end in
a local minimum, docs/calibration.md 11); ``--no-start`` starts them at the prior mean, as
before the option existed. Their folders end in ``-start`` when started (``designed-k41-start``),
so a run of either kind never reuses the other's. ``--dimension-terms quadratic`` goes to every
verify and design (``--model consistent``, FEM chains: the default ``--model-stiffness fem``);
every stage's folder then ends in ``-quadratic`` (``std-quadratic``, ``design-k41-quadratic``,
``designed-k41-quadratic-start``; summary ``two_stage-k41-quadratic-start.json``).

Writes OUT/two_stage[...].json (every stage's Table 1 drive rows, sources alone, z, z RMS of the
drive sources alone, of every source alone and of every base parameter, fit/noise, the
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
from flexcal.validation.runs.verify import PAPER_DRIVE_FIGURES as PAPER  # noqa: E402  Table 1: um, mm, % (relative)


def model_options(args) -> list[str]:
    """The calibration model's options, the same for every verify and design of a run."""
    return ["--model", args.model, "--dimension-terms", args.dimension_terms]


def verify_argv(out: Path, args, trajectory: Path | None = None, start: Path | None = None) -> list[str]:
    """bench_design_heldout's argv for one verify stage: the standard trajectory (trajectory None)
    or a designed one, its fits started at ``start`` (a report.json; None: the prior mean)."""
    argv = ["--out", str(out), "--seed", str(args.seed), "--scenario", args.scenario, *model_options(args),
            "--noise-urad", str(args.noise_urad), "--walk-seed", str(args.walk_seed)]
    if trajectory is not None:
        argv += ["--trajectory", str(trajectory)]
    if start is not None:
        argv += ["--start", str(start)]
    return argv


def design_argv(out: Path, args, report: Path, extra: list[str]) -> list[str]:
    """flexcal design's argv: the design at ``report``'s identified values."""
    return ["design", "--scenario", args.scenario, "--at", str(report), *model_options(args),
            "--inadequacy", "none", "--noise-urad", str(args.noise_urad), "--out", str(out), "--force", *extra]


def _z_rms(values) -> float | None:
    values = [v for v in values if v is not None]
    return (sum(v * v for v in values) / len(values)) ** 0.5 if values else None


def _verify(out: Path, args, trajectory: Path | None, redo: bool, start: Path | None = None) -> dict:
    done = out / "heldout.json"
    if not done.exists() or redo:
        argv = verify_argv(out, args, trajectory, start)
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
    heldout["z_rms_drives_alone"] = _z_rms(d["z"] for d in heldout["drives"].values() if d["alone"])
    # every source identified alone (a pure base parameter, drive or not) and every base parameter
    rows = {r["name"]: r for r in report["parameters"]}
    base = report.get("base_parameters", {})
    pure = base.get("pure", [])
    heldout["z_rms_pure"] = _z_rms(rows[n].get("z_score") for n in pure)
    heldout["n_pure"] = len(pure)
    heldout["z_rms_base"] = base.get("z_rms")
    heldout["n_base"] = base.get("n_z_scores", len(base.get("rows", [])))  # reports before session 23 left some rows out
    heldout["start"] = str(start) if start is not None else None
    return heldout


def _design(out: Path, args, report: Path, extra: list[str], redo: bool) -> dict:
    done = out / "report.json"
    if not done.exists() or redo:
        from flexcal.validation.cli import main as main_cli

        argv = design_argv(out, args, report, extra)
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

    def rms(key, n):
        return "-" if run.get(key) is None else f"{run[key]:.2f} ({run.get(n)})"

    return (f"| {name} | {run['n_points']} | {len(run['alone'])}: {', '.join(run['alone'])} | {cell('x0')} | {cell('CL')} "
            f"| {cell('mu')} | {z} | {rms('z_rms_pure', 'n_pure')} | {rms('z_rms_base', 'n_base')} "
            f"| {run['fit_over_noise']:.2f} | {floor_text} | {run['heldout_rms_urad']:.3f} "
            f"(floor {run['heldout_floor_urad']:.3f}) | {run.get('verify_wall_s') or float('nan'):.0f} |")


def _variant(args) -> str:
    """The designed stage's folder suffix: "" for the plain D-optimal design, "-kK[-region][-criterion]"
    otherwise (the criterion only when not D, so the D runs keep their folders)."""
    criterion = getattr(args, "criterion", "D")
    if args.keep_standard == 0 and args.region == "workspace" and criterion == "D":
        return ""
    return (f"-k{args.keep_standard}" + ("" if args.region == "workspace" else f"-{args.region}")
            + ("" if criterion == "D" else f"-{criterion}"))


def _terms(args) -> str:
    """Every stage's folder suffix for the model's dimension terms: "" for linear (the folders of
    the runs made before the option existed), "-quadratic" otherwise."""
    return "" if args.dimension_terms == "linear" else f"-{args.dimension_terms}"


def _started(args) -> str:
    """A designed verify's folder suffix: "-start" when its fits start at stage 1's estimate
    (the folders of the runs made before --start existed started at the prior mean)."""
    return "-start" if args.start else ""


def stage_plan(out: Path, args) -> dict:
    """The stages a run makes, in order: name -> folder, and for a verify its trajectory and
    start (stage 1's report.json with --start, else None), for a design its argv's extra options.
    Each variant (K, region, dimension terms, start) has its own folders, so variants share
    nothing they would overwrite; the designed verifies share the design of their variant."""
    terms, started = _terms(args), _started(args)
    std = out / f"std{terms}"
    start = std / "report.json" if args.start else None
    plan = {"standard": {"folder": std, "trajectory": None, "start": None}}
    designs = []
    if not args.skip_designed:
        variant = _variant(args)
        designs.append((f"designed{variant}", out / f"design{variant}{terms}",
                        ["--candidates", str(args.candidates), "--keep-standard", str(args.keep_standard),
                         "--region", args.region, "--criterion", args.criterion],
                        out / f"designed{variant}{terms}{started}"))
    if args.combined:
        designs.append(("combined", out / f"design-combined{terms}",
                        ["--points", "154", "--keep-standard", "77", "--candidates", str(args.combined_candidates)],
                        out / f"combined{terms}{started}"))
    for name, design, extra, folder in designs:
        plan[f"design:{name}"] = {"folder": design, "at": std / "report.json", "extra": extra}
        plan[name] = {"folder": folder, "trajectory": design / "trajectory.csv", "start": start}
    return plan


def summary_path(out: Path, args) -> Path:
    return out / f"two_stage{_variant(args)}{_terms(args)}{_started(args)}.json"


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
    parser.add_argument("--criterion", default="D", choices=("D", "I", "drives"),
                        help="the designed stage's criterion (flexcal design --criterion; default D)")
    parser.add_argument("--combined", action="store_true",
                        help="also the standard trajectory followed by 77 designed postures (one measurement)")
    parser.add_argument("--combined-candidates", type=int, default=500)
    parser.add_argument("--skip-designed", action="store_true", help="only the standard and the combined stages")
    parser.add_argument("--dimension-terms", default="linear", choices=("linear", "quadratic"),
                        help="the consistent model's dimension terms (flexcal verify/design --dimension-terms), "
                             "for every verify and design of the run")
    parser.add_argument("--start", action=argparse.BooleanOptionalAction, default=True,
                        help="the designed verifies start every fit at stage 1's estimate (flexcal verify --start "
                             "std/report.json; default on; --no-start: at the prior mean)")
    parser.add_argument("--redo", action="store_true", help="rerun stages whose results are already in --out")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    threads = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}

    summary = {"scenario": args.scenario, "seed": args.seed, "model": args.model, "noise_urad": args.noise_urad,
               "dimension_terms": args.dimension_terms, "criterion": args.criterion, "start": args.start,
               "threads": threads, "paper": PAPER,
               "runs": {}, "designs": {}}
    for name, stage in stage_plan(out, args).items():
        if name.startswith("design:"):
            summary["designs"][name.split(":", 1)[1]] = _design(stage["folder"], args, stage["at"], stage["extra"],
                                                               args.redo)
        else:
            summary["runs"][name] = _verify(stage["folder"], args, stage["trajectory"], args.redo, stage["start"])
    for name, run in summary["runs"].items():
        if name != "standard":
            summary[f"{name}_vs_standard"] = _beats(run, summary["runs"]["standard"])
    summary_path(out, args).write_text(json.dumps(summary, indent=1))

    print(f"{args.scenario} seed {args.seed}, --model {args.model}, {args.noise_urad} urad; errors x0 um, CL mm, mu % "
          "(relative); *: not identified alone")
    print("| trajectory | points | alone | x0 D1/D2/D3 | CL D1/D2/D3 | mu D1/D2/D3 | z (alone) | z RMS alone (n) "
          "| z RMS base (n) | fit/noise | floor RMS x/y/z urad | held-out RMS urad | verify wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, run in summary["runs"].items():
        print(_row(name, run))
    for key in summary:
        if key.endswith("_vs_standard"):
            print(key, json.dumps(summary[key]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
