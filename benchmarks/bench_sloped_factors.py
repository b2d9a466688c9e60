"""The FEM compliance factors with their slopes against the as-built chains' own factors.

    .venv/bin/python benchmarks/bench_sloped_factors.py [--provider fem|fem-rigid] [--scenario table1]
        [--seeds 1,2,3]

For each seed's as-built chains (the scenario's errors drawn with it): the factors the model uses,
``f(P0) + sum_k g_k r_k`` (``model_correction.compliance_factors`` and ``compliance_slopes`` at the
nominal chains, r_k the relative dimension changes), against the provider's own factors of the
as-built chain; max % of the factor over the chains, per entry group (axial / uy entries / uz
entries / torsion). Rows: the constant factors, the provider's slopes, and for ``fem`` (cuts tied) also
the rigidly joined segments' relative slopes times the tied factor (the alternative rejected in
docs/model.md 7, "Session 25"). Not a test: the figures go into docs/model.md.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

FIELDS = ("width", "fillet", "hinge_length", "thickness_1", "thickness_2")  # DIMENSION_SYMBOLS' order
GROUPS = {"axial": [0], "uy": [1, 2, 3], "uz": [4, 5, 6], "torsion": [7]}


def _factors(chain, provider, material) -> np.ndarray:
    from flexcal.model.chain import chain_compliance_matrix
    from flexcal.model.hinge import ENTRY_INDEX
    from flexcal.validation.runs.model_correction import provider_chain_compliance

    richer, closed = provider_chain_compliance(chain, provider), chain_compliance_matrix(chain, material)
    return np.array([richer[i, j] / closed[i, j] for i, j in ENTRY_INDEX.values()])


def main(argv=None) -> int:
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import as_built
    from flexcal.validation.runs.model_correction import compliance_factors, compliance_slopes

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--provider", default="fem", choices=("fem", "fem-rigid"))
    parser.add_argument("--scenario", default="table1")
    parser.add_argument("--seeds", default="1,2,3")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    provider = stiffness_provider(args.provider, progress=False, workers=None)
    space = load_scenario(args.scenario).space
    factors, slopes = compliance_factors(space, provider), compliance_slopes(space, provider)
    variants = {"constant factors": lambda c, r: factors[c], "the provider's slopes": lambda c, r: factors[c] + r @ slopes[c]}
    if args.provider == "fem":
        rigid = stiffness_provider("fem-rigid", progress=False, workers=None)
        rigid_factors, rigid_slopes = compliance_factors(space, rigid), compliance_slopes(space, rigid)
        variants["the rigid cuts' relative slopes"] = lambda c, r: factors[c] * (1 + r @ rigid_slopes[c] / rigid_factors[c])
    print(f"bench_sloped_factors: {args.scenario}, provider {args.provider}; max % of the factor over the chains, "
          "axial / uy / uz / torsion")
    print("| seed | " + " | ".join(variants) + " |")
    print("|---|" + "---|" * len(variants))
    for seed in (int(s) for s in args.seeds.split(",")):
        scenario = load_scenario(args.scenario, seed=seed)
        mechanism = as_built(scenario.space, scenario.values)[0]
        errors = {name: [] for name in variants}
        for c, (nominal, actual) in enumerate(zip(space.mechanism.chains, mechanism.chains)):
            r = np.array([getattr(actual.chain, f) / getattr(nominal.chain, f) - 1.0 for f in FIELDS])
            own = _factors(actual.chain, provider, mechanism.material)
            for name, model in variants.items():
                errors[name].append(np.abs(model(c, r) / own - 1.0) * 100.0)
        cells = [" / ".join(f"{np.array(e)[:, g].max():.3f}" for g in GROUPS.values()) for e in errors.values()]
        print(f"| {seed} | " + " | ".join(cells) + " |", flush=True)
    print(f"bench_sloped_factors: {time.perf_counter() - start:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
