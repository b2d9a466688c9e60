"""``flexcal diagnose-benchmark``: the blind benchmark of the gap diagnosis.

For every library effect, ``none`` and the out-of-library effects, at the grid's
magnitudes (multiples of the sensor noise) and seeds: prototype data with the effect
injected, the answer kept in ``DIR/answers.json`` (never given to the diagnosis), the
diagnosis, the score. Writes DIR/report.json (rows, confusion matrix, goals), report.md,
answers.json, diagnosis_confusion.png, diagnosis_detection.png, diagnosis_closure.png.

Each finished case is written at once to DIR/cases/<id>.json (row and answer; the id
hashes the case and the settings, not the code version: use a new DIR after a code
change). A case already there is not run again, so an interrupted or partly failed grid
resumes where it stopped; a case that raises is listed in the report and the command
exits 1 after writing the figures of the others. The cases run one after the other in
this process by default, in parallel on the shared executor with ``--workers N`` (local
worker processes) or ``--scheduler ADDRESS`` (docs/scale.md); with ``--provider fem`` the
as-built mounts' chains are built first (tied, or their segments for a rigid provider), by default on one thread per core. With
``--trajectory FILE`` (``flexcal design``'s trajectory.csv) every case is measured along
that trajectory, ``--cycles`` times, instead of the standard one; the report names it
(file and content hash), and the case ids include its hash. With ``--mount FILE`` the
table1 errors are drawn on that mount (its standard trajectory, its baseline model, its
null); each case's spec holds the mount, so its id differs from the reference mount's.

    flexcal diagnose-benchmark --out runs/bench                 # small grid, analytic prototype
    flexcal diagnose-benchmark --grid full --provider fem --out runs/bench-full
    flexcal diagnose-benchmark --trajectory runs/design/trajectory.csv --out runs/bench-designed
    flexcal diagnose-benchmark --mount examples/mirror600.mount.toml --out runs/bench-mirror
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from ..diagnosis.null import NULL_SEEDS

__all__ = ["configure", "run", "EXAMPLES"]

# --out holds the finished designs of an earlier run, which a rerun resumes (no --force)
RESUMES_OUT = True

EXAMPLES = ("flexcal diagnose-benchmark --out runs/bench",
            "flexcal diagnose-benchmark --grid full --provider fem --out runs/bench-full",
            "flexcal design --points 77 --model-stiffness closed-form --out runs/design && "
            "flexcal diagnose-benchmark --trajectory runs/design/trajectory.csv --out runs/bench-designed",
            "flexcal diagnose-benchmark --mount examples/mirror600.mount.toml --out runs/bench-mirror")


def configure(parser: argparse.ArgumentParser) -> None:
    from .options import add_out, add_seed, add_trajectory

    parser.add_argument("--grid", choices=("tiny", "small", "full"), default="small",
                        help="tiny: 10x noise, one seed; small (default): 3x and 10x, one seed, 4 none seeds; "
                             "full: 1x, 3x, 10x, three seeds, 10 none seeds")
    parser.add_argument("--provider", choices=("analytic", "fem"), default="analytic",
                        help="prototype segment stiffness (default analytic: fast; fem for the full grid)")
    parser.add_argument("--effects", default=None,
                        help="comma-separated subset of effect ids (default: the whole library, none and the "
                             "out-of-library ids)")
    parser.add_argument("--noise-urad", type=float, default=0.5, help="sensor noise per channel [urad] (0.5)")
    parser.add_argument("--cycles", type=int, default=2,
                        help="the trajectory (standard or --trajectory) measured this often in a row (2)")
    add_trajectory(parser)
    parser.add_argument("--scenario-seed", type=int, default=None,
                        help="one as-built mount (table1 draws and noise) for every case (default: 1000 + the case "
                             "seed; a fixed one keeps the FEM cache warm)")
    add_seed(parser, what="the baseline optimizer of every diagnosis", default=0)
    parser.add_argument("--no-null", action="store_true",
                        help="no null of the trajectory: the fixed significance threshold alone (the diagnosis "
                             "before issue 28); by default `none` files of scenario seeds 1100-1102 along the same "
                             "trajectory are diagnosed first and each term must gain 3x its gain there "
                             "(DIR/null.json)")
    from .options import MODEL_DEFAULTS, add_model_options, add_mount

    add_mount(parser, what="the reference mount (the table1 errors are drawn on it)")
    # the baseline's model: the calibration commands' (and flexcal diagnose's) options and
    # defaults, its chains' stiffness the provider's own unless given (baseline_stiffness)
    add_model_options(parser, stiffness_default="closed-form with --provider analytic, fem with --provider fem",
                      executor_what="the cases (and, with --provider fem, the FEM chain builds)")
    parser.set_defaults(**{**MODEL_DEFAULTS, "model_stiffness": None})
    add_out(parser, what="report.json, report.md, answers.json, diagnosis_*.png, cases/",
            when="each finished case is kept at once in DIR/cases/ and running the same command again resumes; the "
                 "report is written at the end, also when some cases failed (they are listed, exit status 1)")


def baseline_stiffness(provider_name: str) -> str:
    """The chain stiffness of the diagnosis baseline's model for a prototype provider (when
    ``--model-stiffness`` does not say): the one the prototype's segments have (closed form for
    ``analytic``, FEM-informed for ``fem``). What is withheld from the diagnosis is the effect,
    not the mechanism's stiffness model; a user calibrates with the best model of their mount."""
    return "closed-form" if provider_name == "analytic" else "fem"


def case_spec(effect_id, magnitude, case_seed, *, provider_name, noise_urad, cycles, seed, scenario_seed,
              trajectory: str | None = None, null: bool = False, mount: dict | None = None,
              baseline: dict | None = None) -> dict:
    """Everything that decides one case's row: its id (``design_id`` of this) keys the
    case store, so a rerun with other settings never reuses a row. baseline: the baseline
    model's options (``cli.opening.model_key``; None: the second-order model with the
    provider's stiffness, as before session 28). trajectory: the
    ``trajectory_digest`` of a trajectory file, None for the standard trajectory (no key:
    the ids of standard-trajectory cases stay those of earlier runs); mount: the mount file's
    table (``mount_table``) of ``--mount``, None for the reference mount (no key, likewise)."""
    spec = {"effect": effect_id, "magnitude_noise": float(magnitude), "seed": int(case_seed),
            "provider": provider_name,
            "baseline_model": baseline or {"stiffness": baseline_stiffness(provider_name), "second_order": True},
            "noise_urad": float(noise_urad), "cycles": int(cycles), "baseline_seed": int(seed),
            "scenario_seed": scenario_seed}
    if trajectory is not None:
        spec["trajectory"] = trajectory
    if null:
        spec["null_seeds"] = list(NULL_SEEDS)
    if mount is not None:
        spec["mount"] = mount
    return spec


def spec_mechanism(spec: dict):
    """The ``MechanismParams`` of a case spec's mount (None: the reference mount)."""
    from flexcal.geometry.mount import mount_from_table

    return None if spec.get("mount") is None else mount_from_table(spec["mount"], source="the case's mount")


def grid_cases(ids, grid) -> list[tuple[str, float, int]]:
    """(effect id, magnitude [x noise], case seed) of every case of a grid, in run order."""
    from ..diagnosis.benchmark import GRIDS
    from ..effects.library import NONE

    magnitudes, seeds, none_seeds = GRIDS[grid]
    cases = []
    for effect_id in ids:
        if effect_id == NONE:
            cases += [(NONE, 0.0, s) for s in range(none_seeds)]
        else:
            cases += [(effect_id, m, s) for m in magnitudes for s in seeds]
    return cases


def case_record(spec: dict, *, space=None, trajectory=None, null=None, model_threads: int = 1) -> dict:
    """One case of ``case_spec`` run and scored (a pure function, run on a worker): the
    record {"id", "spec", "row", "answer"} the case store keeps; space: the baseline's model;
    trajectory: (inputs (k, 3) [m], leg (k,)) of one cycle, the one whose digest the spec
    names (None: the standard trajectory); model_threads: the baseline's model threads
    (``calibrate_baseline``'s n_threads: the same bits at any count)."""
    from functools import partial

    from ..prototype.providers import stiffness_provider
    from ..diagnosis.diagnose import run_diagnosis
    from ..diagnosis.baseline import calibrate_baseline
    from ..diagnosis.benchmark import benchmark_measurement, run_case, trajectory_digest
    from ..sweep.space import design_id

    given = None if trajectory is None else trajectory_digest(*trajectory)
    if spec.get("trajectory") != given:
        raise ValueError(f"case {spec['effect']}: its trajectory {spec.get('trajectory') or 'standard'} is not the "
                         f"one given ({given or 'standard'})")
    start = time.perf_counter()
    provider = stiffness_provider(spec["provider"], progress=False)  # FEM: the segments are cached by then
    case = benchmark_measurement(spec["effect"], spec["magnitude_noise"], spec["seed"], provider,
                                 cycles=spec["cycles"], noise_urad=spec["noise_urad"],
                                 scenario_seed=spec["scenario_seed"], trajectory=trajectory,
                                 mechanism=spec_mechanism(spec))
    row = run_case(case, lambda m: run_diagnosis(m, rng=spec["baseline_seed"], null=null,
                                                 baseline=partial(calibrate_baseline, space=space,
                                                                  n_threads=model_threads)))
    row["wall_s"] = time.perf_counter() - start
    return {"id": design_id(spec), "spec": spec, "row": row, "answer": case.answer}


def case_chains(specs) -> list:
    """Every chain of the as-built mounts of ``specs``, in order (the chains their truths ask the
    FEM provider for)."""
    from ..prototype.scenario import load_scenario
    from ..prototype.truth import as_built

    chains = []
    for spec in specs:
        scenario_seed = 1000 + spec["seed"] if spec["scenario_seed"] is None else spec["scenario_seed"]
        scenario = load_scenario("table1", seed=scenario_seed, mount=spec_mechanism(spec))
        mechanism, _, _ = as_built(scenario.space, scenario.values)
        chains += [p.chain for p in mechanism.chains]
    return chains


def benchmark_null(*, provider_name, noise_urad, cycles, seed, space=None, trajectory=None, path=None, log=None,
                   mount: dict | None = None, baseline: dict | None = None):
    """The ``NullModel`` of the benchmark's trajectory: `none` files of ``NULL_SEEDS`` (scenario
    seeds 1100-1102, apart from every grid's cases) diagnosed without a null; read from / kept
    in ``path`` (DIR/null.json) so that a resumed grid uses the same one; mount: the mount
    file's table (None: the reference mount); baseline: the options of ``space``'s model
    (``cli.opening.model_key``), kept in the null. A null.json of another trajectory, mount or
    baseline model is refused."""
    from functools import partial
    from pathlib import Path

    from ..diagnosis.baseline import calibrate_baseline
    from ..diagnosis.benchmark import benchmark_measurement, trajectory_digest
    from ..diagnosis.diagnose import run_diagnosis
    from ..diagnosis.null import check_null_baseline, measure_null, read_null, write_null
    from ..effects.library import NONE
    from ..executor import usable_cores
    from ..prototype.providers import stiffness_provider

    from ..sweep.space import design_id

    label = "standard" if trajectory is None else trajectory_digest(*trajectory)
    if mount is not None:
        label += f" on mount {design_id(mount)}"
    if path is not None and Path(path).exists():
        null = read_null(path)
        if null.trajectory != label:
            raise ValueError(f"{path} is the null of trajectory {null.trajectory!r}, this run's is {label!r}: give a "
                             f"new --out for another trajectory or mount")
        if baseline is not None:
            check_null_baseline(null, baseline, str(path))
        return null
    (log or (lambda text: None))(f"diagnose-benchmark: the null of the trajectory ({len(NULL_SEEDS)} none files)")
    provider = stiffness_provider(provider_name, progress=False)
    mechanism = spec_mechanism({"mount": mount})
    null = measure_null(lambda s: benchmark_measurement(NONE, 0.0, s, provider, cycles=cycles, noise_urad=noise_urad,
                                                        trajectory=trajectory, mechanism=mechanism).measurement,
                        # in this process, one file after the other: the model on every usable core
                        lambda m: run_diagnosis(m, rng=seed, baseline=partial(calibrate_baseline, space=space,
                                                                              n_threads=usable_cores())),
                        NULL_SEEDS, label, baseline)
    if path is not None:
        write_null(path, null)
    return null


def run_benchmark(ids, grid, *, noise_urad, cycles, seed, progress, scenario_seed=None, space=None,
                  provider_name="analytic", store=None, log=None, workers: int | None = 0, scheduler=None,
                  trajectory=None, null=None, mount: dict | None = None, baseline: dict | None = None):
    """(rows, answers, failures) of every case of the grid, rows in grid order; space: the
    baseline's model (default: the baseline's own default), baseline: its options (``case_spec``,
    None: the second-order model); trajectory: (inputs (k, 3) [m],
    leg (k,)) of one cycle every case is measured along (None: the standard trajectory);
    mount: the mount file's table the cases are drawn on (None: the reference mount);
    store: a ``DesignStore`` of
    finished cases (each saved as it finishes; a case already in it is not run again);
    failures: {case label: error text} of the cases that raised (one bad case must not
    sink a two-hour grid). workers / scheduler: the shared executor
    (``flexcal.validation.executor``; 0 or None without a scheduler: one case after the
    other here; None builds the FEM chains on one thread per core, ``segments.prepare_chains``).
    With the FEM provider the as-built mounts' missing chains are built first, all at
    once on the same executor, then the cases run on cached chains."""
    from ..progress import progress_bar
    from ..diagnosis.benchmark import trajectory_digest
    from ..executor import resolve_workers, run_jobs, usable_cores, where
    from ..sweep.space import design_id

    log = log or (lambda text: None)
    digest = None if trajectory is None else trajectory_digest(*trajectory)
    specs, labels = [], {}
    for effect_id, magnitude, case_seed in grid_cases(ids, grid):
        spec = case_spec(effect_id, magnitude, case_seed, provider_name=provider_name, noise_urad=noise_urad,
                         cycles=cycles, seed=seed, scenario_seed=scenario_seed, trajectory=digest,
                         null=null is not None, mount=mount, baseline=baseline)
        specs.append(spec)
        labels[design_id(spec)] = f"{effect_id} {magnitude:g}x seed {case_seed}"
    records = {} if store is None else {i: r for i in labels if (r := store.load(i)) is not None}
    pending = list({design_id(s): s for s in specs if design_id(s) not in records}.values())
    # the cases run in this process unless workers are asked for: worker processes import the
    # FEM stack again; the default (None) builds the FEM segments on threads (plan_local_builds)
    n_workers = resolve_workers(0 if workers is None else workers, len(pending))
    if pending:
        log(f"diagnose-benchmark: {len(labels)} cases, {len(labels) - len(pending)} already done, {len(pending)} to "
            f"run on {where(n_workers, scheduler)}")
    if pending and provider_name == "fem":  # what the truths will ask for: tied chains (segments.prepare_chains)
        from ..prototype.providers import stiffness_provider
        from ..prototype.segments import prepare_chains

        prepare_chains(stiffness_provider(provider_name, progress=progress, workers=workers, scheduler=scheduler),
                       case_chains(pending))
    failures = {}
    # the cases one after the other here: the baseline's model on every usable core; on parallel
    # workers one thread each (the same bits either way)
    options = {"space": space, "trajectory": trajectory, "null": null,
               "model_threads": usable_cores() if n_workers == 0 and scheduler is None else 1}
    with progress_bar(len(specs), "diagnose-benchmark", enabled=progress, unit="case") as bar:
        bar.update(len(specs) - len(pending))
        def on_done(_spec, record):
            if store is not None:
                store.save(record)
            records[record["id"]] = record
            bar.update(1)

        for identifier, text in run_jobs(pending, case_record, on_done, key=design_id, workers=n_workers,
                                         scheduler=scheduler, job_options=options, task_prefix="case").items():
            failures[labels[identifier]] = text
            log(f"diagnose-benchmark: case {labels[identifier]} failed: {text}")
    done = [records[design_id(s)] for s in specs if design_id(s) in records]
    return [r["row"] for r in done], [r["answer"] for r in done], failures


def _trajectory(args: argparse.Namespace):
    """((inputs (k, 3) [m], leg (k,)) of ``--trajectory`` or None, its report entry);
    ValueError (one line) for a file the diagnosis could not use."""
    from ..diagnosis.benchmark import repeated_trajectory, trajectory_digest
    from ..diagnosis.diagnose import MIN_POINTS
    from ..prototype.scenario import read_trajectory

    if not args.trajectory:
        return None, {"kind": "standard", "n_points": 77}
    inputs, leg = read_trajectory(args.trajectory)
    n_points = repeated_trajectory(args.cycles, (inputs, leg))[0].shape[0]
    if n_points < MIN_POINTS:
        raise ValueError(f"--trajectory {args.trajectory}: {inputs.shape[0]} points x{args.cycles} cycles = "
                         f"{n_points} points; the diagnosis needs at least {MIN_POINTS}")
    return (inputs, leg), {"kind": "file", "file": str(args.trajectory), "sha256": trajectory_digest(inputs, leg),
                           "n_points": int(inputs.shape[0]), "n_legs": len(np.unique(leg[leg > 0]))}


def run(args: argparse.Namespace) -> int:
    from .common import show_progress
    from ..diagnosis.benchmark import summarize
    from .options import executor_options
    from ..diagnosis.plots import plot_benchmark
    from ..reports.diagnose_benchmark import benchmark_markdown
    from ..effects.library import EFFECT_IDS, LIBRARY, NONE, OUT_OF_LIBRARY_IDS
    from ..output import out_folder, staged_output, write_json, write_report
    from ..sweep.run import DesignStore

    if args.noise_urad <= 0:
        raise ValueError(f"--noise-urad={args.noise_urad} must be > 0 (magnitudes are multiples of it)")
    if args.cycles < 2:
        raise ValueError(f"--cycles={args.cycles} must be >= 2 so that every leg's motion repeats in another cycle")
    from .opening import calibration_model, check_model_options, model_key

    args.model_stiffness = args.model_stiffness or baseline_stiffness(args.provider)
    check_model_options(args)  # before a folder is made
    trajectory, trajectory_report = _trajectory(args)
    ids = list(EFFECT_IDS) + [NONE] + list(OUT_OF_LIBRARY_IDS)
    if args.effects:
        ids = [e.strip() for e in args.effects.split(",") if e.strip()]
        unknown = [e for e in ids if e != NONE and e not in LIBRARY]
        if unknown:
            raise ValueError(f"--effects: unknown id(s) {unknown}; known: {', '.join(LIBRARY)}, none")
    progress = show_progress(args)
    log = (lambda text: print(text, file=sys.stderr)) if progress else (lambda text: None)
    store = DesignStore(out_folder(args.out, resume=True) / "cases")
    executor = executor_options(args)
    from flexcal.geometry.mount import mount_table

    from .options import mount_option

    mechanism = mount_option(args)
    mount = None if mechanism is None else mount_table(mechanism)  # the physics only: the id is not the path
    space, baseline = calibration_model(args, mechanism, progress=progress), model_key(args)
    try:
        null = None if args.no_null else benchmark_null(
            provider_name=args.provider, noise_urad=args.noise_urad, cycles=args.cycles, seed=args.seed, space=space,
            trajectory=trajectory, path=store.folder.parent / "null.json", log=log, mount=mount, baseline=baseline)
        rows, answers, failures = run_benchmark(
            ids, args.grid, noise_urad=args.noise_urad, cycles=args.cycles, seed=args.seed,
            progress=progress, scenario_seed=args.scenario_seed, provider_name=args.provider, store=store, log=log,
            space=space, trajectory=trajectory, null=null, mount=mount, baseline=baseline, **executor)
    except KeyboardInterrupt:
        log(f"diagnose-benchmark: interrupted; finished cases are kept in {store.folder}, run the same command "
            f"again to resume")
        raise
    if not rows:
        raise RuntimeError(f"every case failed, e.g. {next(iter(failures.values()))}")
    summary = summarize(rows)
    report = {"grid": args.grid, "provider": args.provider, "scenario_seed": args.scenario_seed,
              "baseline_model": baseline,
              "noise_urad": args.noise_urad, "cycles": args.cycles, "trajectory": trajectory_report,
              "mount": args.mount,
              "out_of_library": list(OUT_OF_LIBRARY_IDS), "null": None if null is None else null.as_dict(),
              "rows": rows, "failures": failures, "summary": summary,
              "note": "answers.json holds what was injected; the diagnosis only received the measurement"}
    with staged_output(args.out, resume=True) as staging:
        write_json(staging / "answers.json", answers)
        write_report(staging, report)
        (staging / "report.md").write_text(benchmark_markdown(report))
        plot_benchmark(staging, rows, summary)
    if progress:
        goals = summary["goals"]
        print("flexcal diagnose-benchmark: " + "; ".join(
            f"{k} {g['measured']:.3f} ({'met' if g['met'] else 'missed'} by {abs(g['margin']):.3f})"
            for k, g in goals.items()) + f"; wrote {args.out}/report.json")
    if failures:
        print(f"flexcal diagnose-benchmark: {len(failures)} case(s) failed (listed in {args.out}/report.json and "
              f"report.md; the figures cover the {len(rows)} finished ones); run the same command again to retry "
              f"them", file=sys.stderr)
        return 1
    return 0
