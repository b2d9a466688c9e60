"""How much of large_deflection's injected signature its diagnosis term can fit, on the standard
trajectory and on a design (docs/diagnosis.md, "Issue 28 results (session 28)").

    .venv/bin/python benchmarks/bench_large_deflection_term.py [--trajectory CSV|standard]

The analytic prototype (table1, scenario seed 1000, the trajectory measured twice) with and without
the effect at 3x and 10x the noise (0.5 urad; the benchmark's seed-0 injector), noise free. Of that
signature, the share the baseline's 45 sources absorb (their Jacobian at the true values, central
differences), then the share of what they leave that the library's term (``effects.terms``,
large_deflection) explains, and the same for a candidate term not in the library: each chain's width
sensitivity of the angles times the bend (six parameters; what a first-order stiffness change of one
chain does). Also each term alone, and where the signature lies: the share of its energy at the 20
points where it is largest, and the median of the smallest drive load there against its median over
the trajectory (a drive near zero load is a nut passing through its gap). Not a test: a measurement
of the term's form (~10 s).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

DESIGN = Path(__file__).resolve().parents[1] / "tests" / "data" / "table1_design_k41_drives.csv"


def explained(columns: np.ndarray, signal: np.ndarray) -> float:
    """The share of |signal|^2 the least-squares fit on ``columns`` explains."""
    q, _ = np.linalg.qr(columns)
    left = signal - q @ (q.T @ signal)
    return float(1.0 - left @ left / (signal @ signal))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trajectory", default=str(DESIGN), help="flexcal design's trajectory.csv or 'standard'")
    args = parser.parse_args()

    from flexcal.model.forward import forward
    from flexcal.validation.diagnosis.benchmark import repeated_trajectory
    from flexcal.validation.effects import terms
    from flexcal.validation.effects.library import make_injector
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario, read_trajectory
    from flexcal.validation.prototype.truth import make_truth

    trajectory = None if args.trajectory == "standard" else read_trajectory(args.trajectory)
    scenario = load_scenario("table1", seed=1000, noise_urad=0.5)
    inputs, leg = repeated_trajectory(2, trajectory)
    scenario = dataclasses.replace(scenario, inputs=inputs, leg=leg)
    provider = stiffness_provider("analytic")
    clean = make_truth(scenario, provider)
    space = scenario.space
    values = space.full_values(scenario.values)
    angles = forward(values, inputs, space=space).angles[0]

    sources = []
    for k, i in enumerate(space.active_indices):
        step = 1e-4 * (space.upper[k] - space.lower[k])  # linear range of every source, far above round-off
        plus, minus = values.copy(), values.copy()
        plus[i] += step
        minus[i] -= step
        both = forward(np.stack([plus, minus]), inputs, space=space).angles
        sources.append(((both[0] - both[1]) / (2 * step)).ravel())
    baseline = np.array(sources).T

    data = terms.build_term_data(values, inputs, time=clean.measurement.time, leg=leg, space=space)
    term = terms.TERMS["large_deflection"]
    library = np.array([term.evaluate(np.eye(6)[k] * term.scale[k], data).ravel() for k in range(6)]).T
    bend = np.sum(data.model_angles**2, axis=1) / terms.ANGLE_SCALE**2
    chains = []
    for placement in space.mechanism.chains:
        wider = values.copy()
        wider[space.index(f"{placement.name}.w")] *= 1 + 1e-3  # 0.1 %: the hinge formulas' linear range
        chains.append(((forward(wider, inputs, space=space).angles[0] - angles) / 1e-3 * bend[:, None]).ravel())
    candidate = np.array(chains).T

    from flexcal.validation.effects.injectors import ANGLE_REFERENCE, reference_angle_gain

    gain = np.asarray(reference_angle_gain()).reshape(3, 3)
    commanded = np.sum((inputs @ gain.T) ** 2, axis=1) / ANGLE_REFERENCE**2  # what the injector stiffens by
    print(f"trajectory {args.trajectory}: the injector's bend |G x|^2 / (1 mrad)^2 median {np.median(commanded):.2f}, "
          f"largest {commanded.max():.2f}; the term's |theta|^2 / (1 mrad)^2 median {np.median(bend):.2f}, largest "
          f"{bend.max():.2f}")
    loads = np.abs(forward(values, inputs, space=space).axial_loads[0][:, 3:]).min(axis=1)  # [N] the least-loaded drive
    print("| magnitude | largest stiffness factor | share at its 20 largest points, median least drive load there [N] (all points), "
          "largest point [urad] | "
          "signature RMS [urad] | baseline absorbs | library term, after the baseline | candidate, "
          "after the baseline | library term alone | candidate alone |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for magnitude in (3.0, 10.0):
        injector = make_injector("large_deflection", magnitude * 0.5, np.random.default_rng([0, 7]))
        signal = (make_truth(scenario, provider, effects=(injector,)).run.angles - clean.run.angles).ravel()
        absorbed = explained(baseline, signal)
        left = 1.0 - absorbed

        def after(columns):
            return (explained(np.hstack([baseline, columns]), signal) - absorbed) / left

        stiffest = 1.0 + max(injector.coefficient) * commanded.max()
        energy = np.sum(signal.reshape(-1, 3) ** 2, axis=1)
        top = np.argsort(-energy)[:20]
        where = (f"{energy[top].sum() / energy.sum():.3f}, {np.median(loads[top]):.0f} ({np.median(loads):.0f}), "
                 f"{np.sqrt(energy.max()) * 1e6:.0f}")
        print(f"| {magnitude:g}x | {stiffest:.2f} | {where} | {np.sqrt(np.mean(signal**2)) * 1e6:.1f} | {absorbed:.3f} | {after(library):.3f} | "
              f"{after(candidate):.3f} | {explained(library, signal):.3f} | {explained(candidate, signal):.3f} |")


if __name__ == "__main__":
    main()
