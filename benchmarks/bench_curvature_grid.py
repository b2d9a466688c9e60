"""The compliance curvatures' factor error at the as-built chains, and their mixed entries from a coarser grid
(docs/model.md 11, session 20).

    .venv/bin/python benchmarks/bench_curvature_grid.py [--scenario table1] [--seeds 1,2,3] [--grids 3,4]
        [--all-terms-grids 4,5]

The FEM compliance factors of the scenario's nominal chains to first order (``compliance_slopes``) and
to second order (``dimension_terms.compliance_curvatures``, the prototype's grid) against the as-built
chains' own FEM factors (``as_built`` of each seed's true values), largest error per group, % of the
factor: the driving chains' uz entries (D1 / D2 / D3), every entry but torsion over all chains, torsion.
``--grids N,..``: the same with the mixed entries measured on the mapped grid at N through the thinnest
section (``fem_provider(...).on_grid(N)``, its own cache keys) as a relative curvature times the factor
on the prototype's grid, the diagonal from the prototype's grid, with the CPU of the coarse grid's
curvature builds (process CPU, build threads included; cold only if its segments are not cached).
``--all-terms-grids N,..``: the slopes and every curvature on that grid (``elements_through``), as
relative ones times the factor on the prototype's grid (docs/model.md 11, session 36).
Not a test (cold, the FEM chains take minutes).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _row(label, model, built) -> str:
    error = 100.0 * np.abs(model / built - 1.0)
    return (f"| {label} | " + " / ".join(f"{error[c, 4:7].max():.3f}" for c in (3, 4, 5))
            + f" | {error[:, :7].max():.3f} | {error[:, 7].max():.3f} |")


def main(argv=None) -> int:
    from flexcal.model.parameters import DIMENSION_SYMBOLS, parameter_space
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import as_built
    from flexcal.validation.runs.dimension_terms import compliance_curvatures
    from flexcal.validation.runs.model_correction import compliance_factors, compliance_slopes

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="table1")
    parser.add_argument("--seeds", default="1,2,3")
    parser.add_argument("--grids", default="", help="elements through the thinnest section of the mixed entries' grid")
    parser.add_argument("--all-terms-grids", default="",
                        help="elements through the thinnest section of a grid for the slopes and every curvature "
                             "(relative ones times the factor on the prototype's grid; docs/model.md 11, session 36)")
    args = parser.parse_args(argv)
    provider = stiffness_provider("fem", progress=False, workers=None)
    space = load_scenario(args.scenario).space
    factors, slopes = compliance_factors(space, provider), compliance_slopes(space, provider)
    curvatures = {"prototype's grid": compliance_curvatures(space, provider)}
    for n in (float(v) for v in args.grids.split(",") if v):
        coarse = provider.on_grid(n)
        start = time.process_time()
        mixed = compliance_curvatures(space, coarse) * (factors / compliance_factors(space, coarse))[:, None, None, :]
        print(f"mixed entries on {n:g} through: {time.process_time() - start:.1f} s CPU")
        diagonal = np.arange(len(DIMENSION_SYMBOLS))
        mixed[:, diagonal, diagonal] = curvatures["prototype's grid"][:, diagonal, diagonal]
        curvatures[f"mixed entries on {n:g} through"] = mixed
    sloped = {}  # label: (slopes, curvatures) on another grid, the first order's own
    for n in (float(v) for v in args.all_terms_grids.split(",") if v):
        start = time.perf_counter()
        terms = (compliance_slopes(space, provider, elements_through=n),
                 compliance_curvatures(space, provider, elements_through=n))
        print(f"slopes and curvatures on {n:g} through: {time.perf_counter() - start:.1f} s wall")
        sloped[f"slopes and curvatures on {n:g} through"] = terms
    print("\n| seed, factors | uz D1 / D2 / D3 % | all but torsion % | torsion % |\n|---|---|---|---|")
    for seed in (int(s) for s in args.seeds.split(",")):
        scenario = load_scenario(args.scenario, seed=seed)
        names = scenario.space.all_names
        built = compliance_factors(parameter_space(as_built(scenario.space, scenario.values)[0]), provider)
        relative = np.array([[scenario.values[names.index(f"{p.name}.{s}")]
                              / scenario.space.nominal_full[names.index(f"{p.name}.{s}")] - 1.0 for s in DIMENSION_SYMBOLS]
                             for p in space.mechanism.chains])
        linear = factors + np.einsum("ck,cke->ce", relative, slopes)
        print(_row(f"{seed}, linear slopes", linear, built))
        for label, h in curvatures.items():
            print(_row(f"{seed}, + curvatures, {label}", linear + 0.5 * np.einsum("ck,cm,ckme->ce", relative, relative, h),
                       built))
        for label, (g, h) in sloped.items():
            print(_row(f"{seed}, {label}", factors + np.einsum("ck,cke->ce", relative, g)
                       + 0.5 * np.einsum("ck,cm,ckme->ce", relative, relative, h), built))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
