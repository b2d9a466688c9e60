"""The model's dimension terms with every moved chain on its nominal chain's cells: what a shape
derivative would give (issue 26's cold time; docs/model.md 11, "Session 37").

    .venv/bin/python benchmarks/bench_morphed_terms.py [--scenario table1] [--walks 3]
        [--trajectory table1=tests/data/table1_design_k41_drives.csv] [--morph template|velocity]
        [--morphed-truth] [--scenario-seed N] [--difference-step 0.01]

The model's slopes and curvatures are finite differences of tied FEM chains built at +-3 % of a
dimension (``runs.model_correction.compliance_slopes``, ``runs.dimension_terms``); each moved
chain is meshed again with the mapped mesher's own cell counts, which change inside +-3 % of a,
l and t1 (session 16). A derivative of the nominal chain's condensation (U^T dK U on the nominal
factors: no build per moved chain, the route to issue 26's 1.5 min) is the limit of differences on
one connectivity. Before building it, this measures whether terms on one connectivity are good
enough: every moved chain is condensed on its nominal chain's cells, by ``--morph`` "template"
(the default: its own geometry meshed on the nominal segments' cells,
``fem.mesh_mapped_chain.template_grid``) or "velocity" (the nominal nodes moved along the mapped
mesher's node velocity, X0 + sum_k r_k V_k, V_k from a relative step ``--step``), then the same
differences, factors and shortening slopes as the default (the nominal chains themselves are the
provider's). ``--morphed-truth``: the truth's as-built chains on their nominal chains' cells too (a
prototype whose stiffness is smooth in the dimensions). Printed: ``bench_form_error``'s rows (the
form error at the true values) of the default terms and of the terms on one connectivity. Each
moved chain is a full condensation here: a measurement of accuracy, not a faster method.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import numpy as np


def morphed_tied_provider(provider, space, step: float, method: str = "template"):
    """A tied provider that gives ``provider``'s chains for the nominal chains of ``space`` and,
    for a chain that moves one or two of their dimensions, its K_chain condensed on the nominal
    chain's segment meshes morphed to it (module docstring): ``method`` "template", the chain's own
    geometry meshed on the nominal segments' cells (``fem.mesh_mapped_chain.template_grid``);
    "velocity", the nominal nodes moved along the mapped mesher's node velocity (linear in the
    change, so a fillet's nodes leave its arc at second order)."""
    from flexcal.fem.cut_warping import chain_twist_stiffness, rigid_part_stiffness
    from flexcal.fem.mesh import TetMesh
    from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain_mirror_part
    from flexcal.model.parameters import DIMENSION_FIELDS
    from flexcal.validation.prototype.cut_fields import (chain_order_matrices, cut_orders, interface_condensed,
                                                         mirror_part)
    from flexcal.validation.prototype.segments import same_design
    from flexcal.validation.prototype.tied_chains import _tied_plan

    mech = space.mechanism
    design = same_design(mech.chains)
    nominals = [p.chain for c, p in enumerate(mech.chains) if design[c] == c]
    through = provider.elements_through_thickness
    memo: dict = {}

    fields = [*DIMENSION_FIELDS.values(), "length"]

    def relative_moves(chain):
        """(nominal chain, {field: relative change}) of a chain that moves the five dimensions and
        the length of a nominal one by <= 12 %, None for any other chain."""
        for nominal in nominals:
            moves = {f: getattr(chain, f) / getattr(nominal, f) - 1.0 for f in fields}
            moves = {f: r for f, r in moves.items() if abs(r) > 1e-12}
            rest = dataclasses.replace(chain, **{f: getattr(nominal, f) for f in fields})
            if rest == nominal and all(abs(r) <= 0.12 for r in moves.values()):
                return nominal, moves
        return None

    def moved(nominal, moves):
        return dataclasses.replace(nominal, **{f: getattr(nominal, f) * (1.0 + r) for f, r in moves.items()})

    def meshes_of(nominal, moves):
        plan0, interfaces, options, _ = _tied_plan(nominal, provider.ties)
        plan, _, _, _ = _tied_plan(moved(nominal, moves), provider.ties)
        out = {}
        for index, (step0, step1) in enumerate(zip(plan0, plan)):
            key = (round(step1[0].x_start, 12), round(step1[0].x_end, 12))
            if key in out:
                continue
            if method == "template":  # the chain's own geometry on the nominal segment's cells
                out[key] = mapped_mesh_chain_mirror_part(step1[0], elements_through_thickness=through,
                                                         template=step0[0], **options)
                continue
            (mesh0, axes) = mirror_part(step0[0], through, options)
            nodes = np.array(mesh0.nodes, dtype=float)
            for field, r in moves.items():
                velocity = None
                for sign in (1.0, -1.0):
                    near = moved(nominal, {field: sign * step})
                    near_plan, _, _, _ = _tied_plan(near, provider.ties)
                    mesh_h, axes_h = mirror_part(near_plan[index][0], through, options)
                    if axes_h == axes and np.array_equal(np.asarray(mesh_h.tets), np.asarray(mesh0.tets)):
                        velocity = sign * (np.asarray(mesh_h.nodes) - np.asarray(mesh0.nodes)) / step
                        break
                if velocity is None:
                    raise ValueError(f"the mapped mesh's connectivity changes on both sides of {field} +-{step:g}")
                nodes = nodes + r * velocity
            out[key] = (TetMesh(nodes, np.asarray(mesh0.tets)), axes)
        return out

    def matrices(chain):
        found = relative_moves(chain)
        if found is None or not found[1]:
            if found is None:
                print(f"  not a morph of a nominal chain: the provider's {chain}", file=sys.stderr, flush=True)
            return {"stiffness": provider.chain_stiffness(chain), "segments": provider.chain_segments(chain)}
        if chain not in memo:
            nominal, moves = found
            meshes = meshes_of(nominal, moves)
            plan, interfaces, options, scale = _tied_plan(moved(nominal, moves), provider.ties)
            condensed = interface_condensed(plan, interfaces, through, options, meshes, scale)
            ordered, orders = chain_order_matrices(plan, condensed, interfaces), cut_orders(plan, interfaces)
            memo[chain] = {"stiffness": chain_twist_stiffness(ordered, orders, scale),
                           "segments": rigid_part_stiffness(ordered, orders, scale)}
            print(f"  morphed chain {len(memo)}: {moves}", file=sys.stderr, flush=True)
        return memo[chain]

    def morphed(chain, x_start, x_end):
        return provider(chain, x_start, x_end)

    morphed.chain_stiffness = lambda chain: matrices(chain)["stiffness"]
    morphed.chain_segments = lambda chain: matrices(chain)["segments"]
    morphed.ties = provider.ties
    morphed.prepare_chains = lambda chains: provider.prepare_chains(
        [c for c in chains if not (relative_moves(c) or (None, {}))[1]])  # the nominal chains and any other
    morphed.description = provider.description + " (moved chains on the nominal meshes, morphed)"
    return morphed


def main(argv=None) -> int:
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
    import bench_form_error

    from flexcal.model.parameters import parameter_space
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="table1")
    parser.add_argument("--walks", type=int, default=3)
    parser.add_argument("--points", type=int, default=60)
    parser.add_argument("--strokes", default="0.5,0.8")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--scenario-seed", type=int, default=None, help="the scenario's errors drawn with this seed "
                        "(default: its own draw)")
    parser.add_argument("--breakaway", type=float, default=2.0)
    parser.add_argument("--morph", default="template", choices=("template", "velocity", "taylor"),
                        help="template: each moved chain meshed on its nominal chain's cells (template_grid); "
                             "velocity: the nominal nodes moved along the mesher's node velocity; taylor: the "
                             "nominal segments' second-order polynomials in the dimensions (tied_taylor, no build "
                             "per moved chain)")
    parser.add_argument("--step", type=float, default=1e-4, help="relative step of the mesher's node velocity")
    parser.add_argument("--difference-step", type=float, default=None,
                        help="every dimension's relative step of the slopes' and curvatures' differences, in both "
                             "sections (default: model_correction.SLOPE_STEPS, 3 %% and the fillet's 2.5 %%): a "
                             "smaller one on the nominal cells is closer to the derivatives")
    parser.add_argument("--trajectory", action="append", default=[], metavar="SCENARIO=FILE")
    parser.add_argument("--morphed-truth", action="store_true",
                        help="the truth's as-built chains morphed from the nominal meshes too (a smooth truth)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    if args.difference_step is not None:  # the one dict every difference reads (bench only)
        from flexcal.validation.runs.model_correction import SLOPE_STEPS

        SLOPE_STEPS.update({symbol: float(args.difference_step) for symbol in SLOPE_STEPS})
    files = dict(item.split("=", 1) for item in args.trajectory)
    provider = stiffness_provider("fem")
    drawn = load_scenario(args.scenario) if args.scenario_seed is None else load_scenario(args.scenario,
                                                                                         seed=args.scenario_seed)
    space = parameter_space(drawn.space.mechanism)
    if args.morph == "taylor":
        from flexcal.validation.prototype.segments import same_design
        from flexcal.validation.prototype.tied_taylor import taylor_tied_provider

        design = same_design(space.mechanism.chains)
        morphed = taylor_tied_provider(provider, [p.chain for c, p in enumerate(space.mechanism.chains)
                                                  if design[c] == c])
    else:
        morphed = morphed_tied_provider(provider, space, args.step, args.morph)
    options = argparse.Namespace(slopes=True, slope_grids="provider", curvatures=True, curvature_pairs="one-sided",
                                 mixed_grids="same", walks=args.walks, points=args.points, seed=args.seed,
                                 provider="fem", corrections=None)
    strokes = [float(s) for s in args.strokes.split(",")]
    truth = morphed if args.morphed_truth else provider
    for label, corrections in (("the default terms (moved chains meshed again)", provider),
                               ("the moved chains on the nominal meshes, morphed", morphed)):
        print(f"\n## {label}; truth: {'morphed' if args.morphed_truth else 'the prototype'}")
        bench_form_error._table(args.scenario, truth, corrections, options, strokes, args.breakaway,
                                files.get(args.scenario), args.scenario_seed)
    print(f"bench_morphed_terms: {time.perf_counter() - start:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
