"""Which drive hysteresis coefficients (D1-D3.mu) a measurement of angles and inputs separates.

    .venv/bin/python benchmarks/bench_mu_rank.py [--scenario paper] [--candidates 2000] [--seed 0]
        [--model consistent|second-order] [--inadequacy]

The model: ``model_space("closed-form", model=...)`` (the consistent model on Eq. 1's chains
by default: analytic, no FEM), at the scenario's true values. Posture sets, each ordered (the
clearance's play state follows the order): the standard trajectory (77 points); the
``--candidates`` postures ``flexcal design`` draws (``calibration.design.candidate_postures``,
uniform in the angular workspace), in their drawn order (a reversal of some actuator at
nearly every step) and in the design's nearest-neighbour tour; and the 77-point D-optimal
designs ``flexcal design`` makes from those candidates, at the prior mean (the command's
default) and at the true values (``flexcal design --at report.json`` after a first
identification). ``--inadequacy`` adds the two designs as ``flexcal design`` makes them by
default (``--inadequacy analytic``: candidates whose model-vs-analytic-prototype error exceeds
the upper quartile of the standard trajectory's are not offered; ~40 s more).

For each: the Jacobian of the angles w.r.t. the 45 sources on the unit box (forward
differences, step ``FD_STEP``, as the identification), its singular values in noise units
per range (0.5 urad) and numerical rank (s_i > 1e-6 s_1, ``identifiability``), each mu's squared
share in the weak directions (s_i < 100: pinned worse than 1 % of a range) and its joint standard
deviation (no prior); the base
parameters (``base_parameters``, max_std 1 % of a range, the pipeline's criterion) at 0.5 urad
and at 0.5 nrad (the noise-free limit), with ``pure``: the mu identified alone, and the
combination each mu enters otherwise; and, per drive, how many postures leave its nut in
the gap (0 < C < CL: the only state in which mu acts, ``C = clip(mu fx, 0, CL)``) and the
point classes S1/S2/S3. Not a test: the figures go into docs/calibration.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

NOISE = 0.5e-6  # [rad] the scenarios' sensor noise
NOISE_FREE = 0.5e-9  # [rad] 1000x below it: the base parameters of a noise-free measurement
MU = ("D1.mu", "D2.mu", "D3.mu")


def setup(scenario: str, model: str):
    from flexcal.model.assembly import mechanism_matrices
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.runs.model_correction import model_space

    truth = load_scenario(scenario)
    space = model_space("closed-form", model=model, mechanism=truth.space.mechanism)
    x_true = space.to_unit(truth.values[space.active_indices])
    gain = mechanism_matrices(space.nominal_full, space).input_gain[0, 3:, 3:]
    return truth, space, x_true, gain


def jacobian_at(space, x_unit: np.ndarray):
    """inputs (n, 3) [m] ordered -> J (3 n, 45) [rad per unit box] at x_unit."""
    from flexcal.calibration.estimation import FD_STEP
    from flexcal.calibration.polish import batched_jacobian_fd
    from flexcal.calibration.problem import CalibrationProblem

    def jacobian(inputs: np.ndarray) -> np.ndarray:
        problem = CalibrationProblem(space=space, inputs=inputs, angles=np.zeros_like(inputs))
        return batched_jacobian_fd(problem.residuals, x_unit, step=FD_STEP)[0]

    return jacobian


def posture_sets(space, gain, x_true, n_candidates: int, seed: int, truth=None) -> dict[str, np.ndarray]:
    """The posture sets of the module doc; with ``truth`` (the scenario) also the designs with the
    command's model-inadequacy filter."""
    from flexcal.calibration.design import candidate_postures, design_trajectory, order_postures
    from flexcal.calibration.estimation import uniform_prior
    from flexcal.model.trajectory import standard_trajectory

    workspace = np.asarray(space.mechanism.workspace)
    standard = standard_trajectory(space.mechanism, n_points=77).inputs
    candidates = candidate_postures(gain, workspace, n_candidates, seed)
    tour = order_postures(candidates, np.abs(np.linalg.solve(gain, workspace)))
    zero = np.zeros((1, 3))
    sets = {"standard (77)": standard,
            f"candidates, drawn order ({n_candidates + 1})": np.vstack([zero, candidates]),
            f"candidates, design tour ({n_candidates + 1})": np.vstack([zero, candidates[tour]])}
    prior = uniform_prior(space.n_params, 1.0)
    filters = [("", None, None)]
    if truth is not None:
        from flexcal.validation.cli.design import MODEL_ERROR_QUANTILE, _inadequacy

        inadequacy = _inadequacy(space, truth.space, False)
        limit = float(np.quantile(np.max(inadequacy(standard), axis=1), MODEL_ERROR_QUANTILE))
        filters.append((f", inadequacy-filtered (limit {limit * 1e6:.3g} urad)", inadequacy, limit))
    for suffix, inadequacy, limit in filters:
        for label, point in (("prior mean", prior.mean), ("true values", x_true)):
            design = design_trajectory(jacobian_at(space, point), gain, workspace, standard, n_points=77,
                                       n_candidates=n_candidates, noise=NOISE, prior_precision=prior.precision,
                                       rng=seed, inadequacy=inadequacy, max_inadequacy=limit)
            note = "" if design.avoided is None else f", {int(design.avoided.sum())} candidates avoided"
            sets[f"D-optimal design at the {label}{suffix} (77{note})"] = design.inputs
    return sets


def analyse(label: str, inputs: np.ndarray, space, truth, x_true) -> None:
    from flexcal.calibration.base_parameters import base_parameters
    from flexcal.model.forward import forward

    start = time.perf_counter()
    J = jacobian_at(space, x_true)(inputs)
    result = forward(truth.values[None], inputs, space=space)
    states, classes = result.chain_states[0], result.point_class[0]
    W = J / NOISE
    s = np.linalg.svd(W, compute_uv=False)
    rank = int(np.sum(s > 1e-6 * s[0]))
    print(f"\n## {label}: {time.perf_counter() - start:.1f} s")
    print("classes S1/S2/S3: " + "/".join(str(int(np.sum(classes == c))) for c in (1, 2, 3)))
    names = space.names
    for i, name in enumerate(MU):
        column = W[:, names.index(name)]
        outside = np.abs(column.reshape(-1, 3))[states[:, i] != 1]
        print(f"D{i + 1}: engaged/gap/far flank {'/'.join(str(int(np.sum(states[:, i] == k))) for k in range(3))}; "
              f"|d theta/d mu| {np.linalg.norm(column):.3g} noise units per range "
              f"(largest outside the gap {outside.max() if outside.size else 0.0:.2g})")
    print(f"rank {rank} of {W.shape[1]} (s > 1e-6 s_1); singular values [noise units per range]:")
    print("  " + " ".join(f"{v:.3g}" for v in s))
    _, _, Vt = np.linalg.svd(W, full_matrices=False)
    weak = Vt[s < 100.0]  # directions the data pin worse than 1 % of a range (identifiability's max_std)
    joint = np.sqrt(np.sum(Vt.T ** 2 / s ** 2, axis=1))  # joint std [fraction of range], no prior
    print("weak directions (s < 100): " + str(weak.shape[0]) + "; " + "; ".join(
        f"{n}: share in them {np.sum(weak[:, names.index(n)] ** 2):.2g}, joint std "
        f"{joint[names.index(n)] * 100:.3g} % of range" for n in MU))
    for noise in (NOISE, NOISE_FREE):
        base = base_parameters(J / noise, names)
        pure = [n for n in MU if n in base.pure()]
        print(f"noise {noise * 1e6:g} urad: {base.n_base} base parameters; mu identified alone: "
              f"{', '.join(pure) or '(none)'}")
        for name in MU:
            if name in pure:
                continue
            if name in base.base:
                print(f"  {name} base, as {base.labels[base.base.index(name)]}")
                continue
            j = base.regrouped.index(name)
            into = [base.labels[k] for k in np.argsort(-np.abs(base.coefficients[:, j]))[:2]
                    if abs(base.coefficients[k, j]) >= 0.05]
            print(f"  {name} regrouped (fixed at its prior), into: {'; '.join(into) or '(no base > 0.05)'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paper")
    parser.add_argument("--model", default="consistent", choices=("consistent", "second-order"))
    parser.add_argument("--candidates", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--inadequacy", action="store_true", help="also the designs with flexcal design's "
                        "default model-inadequacy filter (the analytic prototype at nominal)")
    args = parser.parse_args()
    truth, space, x_true, gain = setup(args.scenario, args.model)
    print(f"# {args.scenario} mount, {args.model} model (closed-form chains), true values; "
          f"noise {NOISE * 1e6:g} urad; candidate seed {args.seed}")
    for label, inputs in posture_sets(space, gain, x_true, args.candidates, args.seed,
                                               truth if args.inadequacy else None).items():
        analyse(label, inputs, space, truth, x_true)


if __name__ == "__main__":
    main()
