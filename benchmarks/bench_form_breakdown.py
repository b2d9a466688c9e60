"""Where the consistent model's form error on one trajectory comes from (docs/model.md 11, session 18).

    .venv/bin/python benchmarks/bench_form_breakdown.py --trajectory DIR/trajectory.csv \
        [--scenario paper] [--seed 1] [--breakaway 2] [--curvatures] [--swaps] [--listing 0.3]

The consistent model with the FEM slopes (``--model consistent``'s space; with ``--curvatures`` the
factors to second order and the shortening correction following the dimensions,
``dimension_terms.curved_space``) at the scenario's true values against the noise-free FEM
prototype along the trajectory (e.g. ``flexcal design``'s trajectory.csv), RMS theta_x / theta_y /
theta_z [urad] (max):

- by posture class S1 / S2 / S3 and by each drive's nut off its flank (the model's);
- ``--listing U``: every posture with an error above U urad: commands, the model's nut offsets
  against the prototype's, its drive loads against the prototype's, the error;
- ``--swaps`` (diagnostics: the as-built chains' own numbers, which no model sees): the model with
  the compliance factors of the as-built chains, with their shortening correction, with both;
  the as-built factors of one chain, one entry group, or one group of one drive at a time; the prototype's nut offsets
  given (CL = 0, commands + the offsets: the chain law without the nuts' amplification, and the
  drives' load errors in their gaps); the closed-form consistent model against the analytic
  prototype (no FEM anywhere);
- ``--path D1,D2``: the model's factors against the FEM chain's along the straight path from the
  nominal chain to the as-built one (4 chain builds each, cold).
Not a test (the FEM prototype and, cold, its segments take minutes).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

GROUPS = {"axial": [0], "uy": [1, 2, 3], "uz": [4, 5, 6], "torsion": [7]}  # model.hinge.ENTRY_INDEX order


def _cell(error: np.ndarray) -> str:
    if len(error) == 0:
        return "-"
    rms = np.sqrt(np.mean(error**2, axis=0)) * 1e6
    return " / ".join(f"{v:.3f}" for v in rms) + f" ({np.abs(error).max() * 1e6:.2f}), n = {len(error)}"


def _groups(label: str, error: np.ndarray, result) -> None:
    print(f"| {label} | all | {_cell(error)} |")
    for c, name in ((1, "S1"), (2, "S2"), (3, "S3")):
        print(f"| | {name} | {_cell(error[result.point_class[0] == c])} |")
    for i in range(3):
        print(f"| | D{i + 1} off its flank | {_cell(error[result.clearance[0][:, i] > 1e-9])} |")


def _listing(inputs, error, result, run, threshold) -> None:
    print(f"\npostures above {threshold:g} urad: commands mm | class | nut offsets model - prototype um (prototype) "
          "| drive loads model - prototype N (prototype) | error urad")
    for p in np.flatnonzero(np.abs(error).max(axis=1) >= threshold * 1e-6):
        offsets, loads = result.clearance[0][p], result.axial_loads[0][p, 3:]
        print(f"{p:3d} | " + " ".join(f"{v * 1e3:6.3f}" for v in inputs[p]) + f" | S{result.point_class[0, p]} | "
              + " ".join(f"{(a - b) * 1e6:+.3f}" for a, b in zip(offsets, run.nut_offsets[p]))
              + " (" + " ".join(f"{b * 1e6:.1f}" for b in run.nut_offsets[p]) + ") | "
              + " ".join(f"{a - b:+.2f}" for a, b in zip(loads, run.axial_loads[p, 3:]))
              + " (" + " ".join(f"{b:.0f}" for b in run.axial_loads[p, 3:]) + ") | "
              + " ".join(f"{v * 1e6:+.2f}" for v in error[p]))


def _swaps(case, inputs, space, run, provider) -> None:
    from flexcal.model.forward import forward
    from flexcal.model.parameters import parameter_space
    from flexcal.validation.prototype.mechanism import apply_mount_offsets
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.truth import as_built, make_truth
    from flexcal.validation.runs.chain_kinematics import shortening_corrections
    from flexcal.validation.runs.model_correction import compliance_factors

    mechanism, offsets, _ = as_built(case.space, case.values)
    built = parameter_space(apply_mount_offsets(mechanism, offsets))
    factors, correction = compliance_factors(built, provider), shortening_corrections(built, provider)
    sloped = space.compliance_slopes and space.compliance_factors
    names = case.space.all_names
    relative = np.array([[case.values[names.index(f"{p.name}.{s}")] / case.space.nominal_full[names.index(f"{p.name}.{s}")]
                          - 1.0 for s in ("w", "a", "l", "t1", "t2")] for p in case.space.mechanism.chains])
    model_factors = np.asarray(space.compliance_factors) + (np.einsum(
        "ck,cke->ce", relative, np.reshape(space.compliance_slopes, (-1, 5, 8))) if sloped else 0.0)
    if space.compliance_curvatures:
        model_factors = model_factors + 0.5 * np.einsum("ck,cm,ckme->ce", relative, relative,
                                                        np.reshape(space.compliance_curvatures, (-1, 5, 5, 8)))
    plain = dataclasses.replace(space, compliance_slopes=(), compliance_curvatures=(), shortening_slopes=())

    def with_factors(f):
        return dataclasses.replace(plain, compliance_factors=tuple(map(tuple, f)))

    def row(label, s, values=case.values, commands=inputs, truth=run.angles):
        print(f"| {label} | {_cell(forward(values, commands, space=s).angles[0] - truth)} |")

    print("\n| swap (the as-built chains' own numbers; a diagnostic) | RMS θx / θy / θz urad (max) |\n|---|---|")
    row("the model", space)
    row("compliance factors of the as-built chains", with_factors(factors))
    row("shortening correction of the as-built chains", dataclasses.replace(
        space, chain_shortening=tuple(correction.ravel()), shortening_slopes=()))
    row("both", dataclasses.replace(with_factors(factors), chain_shortening=tuple(correction.ravel())))
    for c, placement in enumerate(case.space.mechanism.chains):
        f = model_factors.copy()
        f[c] = factors[c]
        row(f"as-built factors of {placement.name} only", with_factors(f))
    for group, index in GROUPS.items():
        f = model_factors.copy()
        f[:, index] = factors[:, index]
        row(f"as-built {group} entries only (all chains)", with_factors(f))
    for c, placement in enumerate(case.space.mechanism.chains):
        if placement.is_driving:
            for group, index in GROUPS.items():
                f = model_factors.copy()
                f[c, index] = factors[c, index]
                row(f"as-built {group} entries of {placement.name} only", with_factors(f))
    given = case.values.copy()
    for i in range(3):
        given[names.index(f"D{i + 1}.CL")] = 0.0
    fixed = forward(given, inputs + run.nut_offsets, space=space)
    print(f"| the prototype's nut offsets given (CL = 0, commands + offsets) | "
          f"{_cell(fixed.angles[0] - run.angles)} |")
    load_error = fixed.axial_loads[0] - run.axial_loads
    for i in range(3):
        gap = run.nut_offsets[:, i] > 1e-9
        if gap.any():
            print(f"|   D{i + 1}'s load error in its gap ({gap.sum()} postures) | RMS "
                  f"{np.sqrt(np.mean(load_error[gap, 3 + i] ** 2)):.3f} N, max {np.abs(load_error[gap, 3 + i]).max():.3f} |")
    analytic = stiffness_provider("analytic", progress=False, workers=None)
    truth = make_truth(case, analytic).run.angles
    closed = dataclasses.replace(parameter_space(case.space.mechanism), second_order=True,
                                 breakaway_force=space.breakaway_force,
                                 chain_shortening=(0.0,) * (36 * len(case.space.mechanism.chains)))
    row("closed-form consistent model against the analytic prototype", closed, truth=truth)


def _path(case, space, provider, names) -> None:
    """The FEM factors along the straight path from the nominal chain to the as-built one (t = 1/4 ..
    1; one chain build each) against the model's (linear slopes, or to second order)."""
    from flexcal.model.parameters import DIMENSION_SYMBOLS
    from flexcal.validation.runs.dimension_terms import moved_chain, moved_factors

    chains = case.space.mechanism.chains
    all_names = case.space.all_names
    print("\nthe model's factors along the path nominal -> as built, error % of the FEM chain's "
          "(entries axial / uy / uz / torsion, largest of each group)")
    for name in names:
        c = [p.name for p in chains].index(name)
        relative = np.array([case.values[all_names.index(f"{name}.{s}")]
                             / case.space.nominal_full[all_names.index(f"{name}.{s}")] - 1.0 for s in DIMENSION_SYMBOLS])
        for t in (0.25, 0.5, 0.75, 1.0):
            fem = moved_factors(chains[c].chain, moved_chain(chains[c].chain, dict(zip(DIMENSION_SYMBOLS, t * relative))),
                           provider, case.space.mechanism.material)
            r = t * relative
            model = np.asarray(space.compliance_factors)[c] + r @ np.reshape(space.compliance_slopes, (-1, 5, 8))[c]
            if space.compliance_curvatures:
                model = model + 0.5 * np.einsum("k,m,kme->e", r, r,
                                                np.reshape(space.compliance_curvatures, (-1, 5, 5, 8))[c])
            error = 100 * (model / fem - 1.0)
            print(f"{name} t = {t:4.2f}: " + " / ".join(f"{error[i][np.argmax(np.abs(error[i]))]:+.3f}"
                                                      for i in GROUPS.values()))


def main(argv=None) -> int:
    from flexcal.model.forward import forward
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario, read_trajectory
    from flexcal.validation.prototype.truth import make_truth
    from flexcal.validation.runs.model_correction import model_space

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trajectory", required=True)
    parser.add_argument("--scenario", default="paper")
    parser.add_argument("--seed", type=int, default=None, help="the scenario's seed (its drawn true values)")
    parser.add_argument("--breakaway", type=float, default=2.0, help="the prototype's and the model's [N]")
    parser.add_argument("--curvatures", action="store_true", help="the model with dimension_terms.curved_space")
    parser.add_argument("--swaps", action="store_true", help="the diagnostic swaps (module docstring)")
    parser.add_argument("--listing", type=float, default=None, metavar="URAD")
    parser.add_argument("--path", default=None, metavar="D1,D2",
                        help="the factors along the path nominal -> as built of these chains (FEM builds)")
    args = parser.parse_args(argv)
    provider = stiffness_provider("fem", progress=False, workers=None)
    scenario = dataclasses.replace(load_scenario(args.scenario, seed=args.seed), breakaway_force=args.breakaway)
    inputs, _ = read_trajectory(args.trajectory)
    case = dataclasses.replace(scenario, inputs=inputs, leg=np.ones(len(inputs), dtype=int))
    space = model_space("fem", model="consistent", mechanism=scenario.space.mechanism,
                        breakaway_force=args.breakaway)
    if args.curvatures:
        from flexcal.validation.runs.dimension_terms import curved_space

        space = curved_space(space, provider)
    run = make_truth(case, provider).run
    result = forward(case.values, inputs, space=space)
    error = result.angles[0] - run.angles
    print(f"{args.scenario} (seed {scenario.seed}), {args.trajectory}: the consistent model"
          f"{' + curvatures, shortening slopes' if args.curvatures else ''} at the true values against the "
          f"noise-free FEM prototype ({args.breakaway:g} N)\n")
    print("| model | postures | RMS θx / θy / θz urad (max) |\n|---|---|---|")
    _groups("consistent", error, result)
    if args.listing is not None:
        _listing(inputs, error, result, run, args.listing)
    if args.swaps:
        _swaps(case, inputs, space, run, provider)
    if args.path:
        _path(case, space, provider, args.path.split(","))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
