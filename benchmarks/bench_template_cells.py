"""An as-built chain's segments on its nominal chain's cells against its own mapped grid.

    .venv/bin/python benchmarks/bench_template_cells.py [--scenario table1] [--scenario-seed N]

``fem.mesh_mapped_chain.template_grid`` meshes a part on the cells of another of its design (the
nominal chain): one connectivity for every dimension, which derivatives of the condensation need
(docs/model.md 11, "Session 37"). The mapper's own grid of an as-built segment has other counts
(more cells through a thicker leaf, docs/scale.md). Printed per meshed leaf segment of the
scenario's as-built chains: the nodes of each mesh and the largest difference of the template
mesh's rigidly condensed 12 x 12 (``mirrored_chain_stiffness``) from the own grid's over the
dominant entries (``reports.fem.DOMINANT_FRACTION``) [%], with the diagonal at end B.
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv=None) -> int:
    from flexcal.fem.condense import mirrored_chain_stiffness
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS, mapped_mesh_chain_mirror_part
    from flexcal.geometry.exact import end_planes, reference_points
    from flexcal.geometry.params import STEEL
    from flexcal.validation.prototype.cut_fields import interface_segments
    from flexcal.validation.prototype.fem_provider import DEFAULT_ELEMENTS_THROUGH
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.segments import same_design
    from flexcal.validation.prototype.truth import as_built
    from flexcal.validation.reports.fem import percent_difference

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="table1")
    parser.add_argument("--scenario-seed", type=int, default=None)
    args = parser.parse_args(argv)
    scenario = (load_scenario(args.scenario) if args.scenario_seed is None
                else load_scenario(args.scenario, seed=args.scenario_seed))
    mechanism, _, _ = as_built(scenario.space, scenario.values)
    nominal_chains = scenario.space.mechanism.chains
    design = same_design(nominal_chains)
    print("| chain | segment start [mm] | nodes own / on the nominal's cells | max diff, dominant entries [%] "
          "| diagonal at B, ux uy uz rx ry rz [%] |")
    print("|---|---:|---|---:|---|")
    for c, placement in enumerate(mechanism.chains):
        nominal = nominal_chains[design[c]].chain
        pairs = zip(interface_segments(nominal, 5)[:2], interface_segments(placement.chain, 5)[:2])
        for (template, *_), (part, *_) in pairs:
            planes, points = end_planes(part), reference_points(part)
            stiffness, nodes = {}, {}
            for name, extra in (("own", {}), ("template", {"template": template})):
                mesh, axes = mapped_mesh_chain_mirror_part(part, elements_through_thickness=DEFAULT_ELEMENTS_THROUGH,
                                                           **PROTOTYPE_CHAIN_OPTIONS, **extra)
                stiffness[name] = mirrored_chain_stiffness(mesh, STEEL, planes["A"], points["A"], planes["B"],
                                                           points["B"], axes)
                nodes[name] = mesh.nodes.shape[0]
            difference = percent_difference(stiffness["template"], stiffness["own"])
            print(f"| {c + 1} | {part.x_start * 1e3:.1f} | {nodes['own']} / {nodes['template']} | "
                  f"{np.nanmax(np.abs(difference)):.4f} | "
                  + " ".join(f"{v:+.4f}" for v in np.diag(difference)[6:]) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
