"""The diagnosis baseline's own form error on a designed trajectory (docs/diagnosis.md, "Issue 28
results (session 27)").

    .venv/bin/python benchmarks/bench_diagnosis_baseline.py [--trajectory CSV] [--seeds 3,100] [--provider fem]

`none` files (no effect injected; table1 errors of scenario seed 1000 + seed, 0.5 urad, the
trajectory measured twice, as ``diagnose-benchmark`` makes them) diagnosed without a null by the
benchmark's baseline until session 27 (the second-order model) and by the calibration commands'
default model (consistent, quadratic dimension terms; the diagnosis baseline since session 28),
baseline optimizer seed 0. Prints, per file and baseline, the answer, its confidence, the three
largest held-out gains [noise variances] and the wall time of the diagnosis: the second-order
baseline's form error shows as gains of several noise variances where the other leaves ~0. Not a
test (cold, the consistent model's FEM terms take ~10 min on 2 cores).
"""

from __future__ import annotations

import argparse
import time
from functools import partial
from pathlib import Path

DESIGN = Path(__file__).resolve().parents[1] / "tests" / "data" / "table1_design_k41_drives.csv"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trajectory", default=str(DESIGN), help="flexcal design's trajectory.csv (default: a README "
                                                                   "design of table1, tests/data)")
    parser.add_argument("--seeds", default="3,100", help="case seeds of the none files (scenario seed 1000 + seed)")
    parser.add_argument("--provider", default="fem", help="the prototype's stiffness provider (fem: the tied truth)")
    args = parser.parse_args()

    from flexcal.validation.cli.diagnose_benchmark import baseline_stiffness
    from flexcal.validation.diagnosis.baseline import calibrate_baseline
    from flexcal.validation.diagnosis.benchmark import benchmark_measurement
    from flexcal.validation.diagnosis.diagnose import run_diagnosis
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import read_trajectory
    from flexcal.validation import cli
    from flexcal.validation.cli.opening import calibration_model

    trajectory = read_trajectory(args.trajectory)
    stiffness = baseline_stiffness(args.provider)  # the chains' stiffness of diagnose-benchmark's baseline
    provider = stiffness_provider(args.provider, progress=False, workers=None)
    start = time.perf_counter()

    def baseline_model(*options):  # the model diagnose-benchmark builds with these options
        parsed = cli.build_parser(only="diagnose-benchmark").parse_args(
            ["diagnose-benchmark", "--out", "unused", "--model-stiffness", stiffness, *options])
        return calibration_model(parsed, None, progress=False)

    baselines = {"second-order (diagnose-benchmark's until session 27)": baseline_model("--model", "second-order"),
                 "consistent + quadratic (verify's; the diagnosis's since session 28)": baseline_model()}
    print(f"models ready in {time.perf_counter() - start:.0f} s")
    print("| none file | baseline | answer | confidence | three largest held-out gains [noise variances] | wall [s] |")
    print("|---|---|---|---|---|---:|")
    for seed in (int(s) for s in args.seeds.split(",")):
        case = benchmark_measurement("none", 0.0, seed, provider, cycles=2, noise_urad=0.5, trajectory=trajectory)
        for name, space in baselines.items():
            start = time.perf_counter()
            report = run_diagnosis(case.measurement, baseline=partial(calibrate_baseline, space=space), rng=0).report
            gains = sorted(report["ranking"], key=lambda r: -r["gain_noise_variances"])[:3]
            shown = ", ".join(f"{r['effect']} {r['gain_noise_variances']:.2f}" for r in gains)
            print(f"| seed {seed} | {name} | {report['top_effect']} | {report['confidence']} | {shown} | "
                  f"{time.perf_counter() - start:.0f} |")


if __name__ == "__main__":
    main()
