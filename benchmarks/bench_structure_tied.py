"""The structure assessment of a scenario's as-built prototype with rigid ties (``--provider fem``)
against tied cuts (``--provider fem``) (docs/structure.md, "Tied cuts"): the first modes,
the support stiffness at O_C (nuts held), the mount's and the chains' buckling factors and the
lowest safety against yield (FEM segments: nominal and over the 77-point standard trajectory),
at the design commands under the payload's weight; with ``--chain-newton D1`` also a Newton
path of that chain alone under its end load times s (A clamped, B held laterally), the lowest
eigenvalue of its tangent against the tangent of the state without load, beside the
linearized "held" factor.

    python benchmarks/bench_structure_tied.py --scenario table1
    python benchmarks/bench_structure_tied.py --scenario table1 --chain-newton D1

Builds the providers' matrices and the FEM segments into the FEM cache (FLEXCAL_CACHE_DIR) if
they are missing (cold ~2 min of CPU). Not a test (tests/test_structure_tied.py).
"""

from __future__ import annotations

import argparse

import numpy as np

AXES = ("x", "y", "z", "rx", "ry", "rz")


def as_built_prototype(scenario_name: str, seed: int | None, provider: str):
    from flexcal.validation.prototype.mechanism import build_prototype
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.truth import as_built

    scenario = load_scenario(scenario_name, seed=seed)
    mechanism, offsets, drives = as_built(scenario.space, scenario.values)
    transmissions = [(x0, cl, mu, scenario.breakaway_force) for x0, cl, mu in drives]
    return build_prototype(mechanism, transmissions, stiffness_provider(provider, progress=False),
                           mount_offsets=offsets)


def figures(prototype) -> dict:
    from flexcal.model.trajectory import standard_trajectory
    from flexcal.validation.blas_threads import single_blas_thread
    from flexcal.validation.structure.fem_segments import FemSegments, chain_peak_stress_fem
    from flexcal.validation.structure.mount import (chain_buckling_factors, mount_buckling_factor, mount_mass,
                                                    mount_modes, nominal_state, payload_mass_matrix, support_stiffness)
    from flexcal.validation.structure.report import _segment_masses
    from flexcal.validation.structure.workspace_report import workspace_section

    fem = FemSegments(prototype.mechanism.material, workers=0)
    masses = _segment_masses(prototype, fem)
    names = [c.name for c in prototype.mechanism.chains]
    with single_blas_thread():
        loaded, unloaded = nominal_state(prototype), nominal_state(prototype, 0.0)
        M = mount_mass(prototype, masses, payload_mass_matrix(prototype.mechanism))
        held = support_stiffness(prototype, loaded.tangent)
        commands = standard_trajectory(prototype.mechanism, n_points=77).inputs
        path = workspace_section(prototype, fem=fem, fem_fine=None, trajectory_commands=commands,
                                 nominal_stiffness=held)["trajectory"]["fem"]["MPa"]
        peak = np.maximum(chain_peak_stress_fem(prototype, loaded.poses, fem), np.array([path[n] for n in names]) * 1e6)
        return {"frequencies_Hz": mount_modes(prototype, loaded, M, 6).frequencies,
                "support_diagonal": np.diag(held), "mount_buckling": mount_buckling_factor(unloaded, loaded),
                "chain_held": chain_buckling_factors(prototype, loaded)["held"], "tension": loaded.tension,
                "safety": prototype.mechanism.material.yield_strength / peak, "names": names}


def chain_newton(prototype, chain: int, factors=(1, 2, 3, 4, 5, 6, 7, 8, 10, 12)) -> list[tuple[float, float]]:
    """(s, mu) along the chain-alone Newton path (module docstring); stops where Newton fails."""
    import scipy.linalg

    from flexcal.validation.prototype.equilibrium import (Loads, NonConvergenceError, SolverSettings, build_assembly,
                                                          evaluate, node_poses, solve_equilibrium)
    from flexcal.validation.prototype.mechanism import frame_stiffness
    from flexcal.validation.prototype.superelement import CoupledStiffness
    from flexcal.validation.structure.mount import nominal_state

    state = nominal_state(prototype)
    a = prototype.assembly
    nodes = node_poses(a, state.poses)
    seg = np.arange(5 * chain, 5 * chain + 5)
    poses = np.concatenate([nodes[a.segment_nodes[seg, 0]], nodes[a.segment_nodes[seg[-1:], 1]]])
    selection = [np.zeros((6, 0))] + [np.eye(6)] * 4 + [np.eye(6)[:, [0, 3, 4, 5]]]  # A clamped, B held
    assembly = build_assembly(selection, np.arange(6), np.broadcast_to(np.eye(4), (6, 4, 4)),
                              np.c_[np.arange(5), np.arange(1, 6)], a.segment_reference_inverse[seg])
    stiffness = frame_stiffness(prototype, prototype.segment_stiffness)
    stiffness = (CoupledStiffness(blocks=stiffness.blocks[chain:chain + 1], segments=np.arange(5)[None])
                 if isinstance(stiffness, CoupledStiffness) else stiffness[seg])
    g = state.segment_gradient[seg[-1], 6:]  # the load holding node B at the state (node axes)
    R, arm = poses[5, :3, :3], 0.01

    def loads(s):
        out = [(5, s * (R @ g[:3]), np.zeros(3))]
        for k in range(3):  # the moment about node axis k as a couple of dead forces
            e, j = np.eye(3)[k], np.eye(3)[(k + 1) % 3]
            force = s * g[3 + k] / (2 * arm) * (R @ np.cross(e, j))
            out += [(5, force, arm * j), (5, -force, -arm * j)]
        return Loads(point_forces=tuple(out))

    K0 = evaluate(assembly, poses, stiffness, loads(0.0), True, prototype.settings.step)[2]
    out, current = [], poses
    for s in factors:
        try:
            current, info = solve_equilibrium(assembly, current, stiffness, loads(float(s)),
                                              SolverSettings(max_iterations=60))
        except NonConvergenceError:
            break
        out.append((float(s), float(scipy.linalg.eigh(info.tangent, K0, eigvals_only=True, subset_by_index=[0, 0])[0])))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="table1")
    parser.add_argument("--seed", type=int)
    parser.add_argument("--chain-newton", metavar="CHAIN", help="a chain's name (D1, ...): its Newton path too")
    args = parser.parse_args()
    results = {}
    for provider in ("fem-rigid", "fem"):
        prototype = as_built_prototype(args.scenario, args.seed, provider)
        results[provider] = figures(prototype)
        if args.chain_newton:
            from flexcal.validation.structure.mount import chain_buckling_factors, nominal_state

            c = results[provider]["names"].index(args.chain_newton)
            linear = chain_buckling_factors(prototype, nominal_state(prototype))["held"][c]
            path = ", ".join(f"{s:g}: {mu:.3f}" for s, mu in chain_newton(prototype, c))
            print(f"{provider}: {args.chain_newton} alone, linearized held factor {linear:.3f}; Newton s: mu = {path}")
    rigid, tied = results["fem-rigid"], results["fem"]

    def row(name, a, b, fmt="{:.4g}"):
        with np.errstate(invalid="ignore"):  # inf -> inf (a chain in tension) reads nan
            change = " ".join(f"{100 * (y / x - 1):+.1f}" for x, y in zip(np.atleast_1d(a), np.atleast_1d(b)))
        print(f"{name}: " + ", ".join(fmt.format(v) for v in np.atleast_1d(a)) + " -> "
              + ", ".join(fmt.format(v) for v in np.atleast_1d(b)) + f"  [%: {change}]")

    print(f"scenario {args.scenario}: rigid ties (fem-rigid) -> tied cuts (fem)")
    row("modes 1-6 [Hz]", rigid["frequencies_Hz"], tied["frequencies_Hz"])
    row("support stiffness, nuts held, " + " ".join(AXES), rigid["support_diagonal"], tied["support_diagonal"])
    row("mount buckling factor", rigid["mount_buckling"], tied["mount_buckling"])
    row("chain held buckling " + " ".join(rigid["names"]), rigid["chain_held"], tied["chain_held"])
    row("chain critical load [N]", rigid["chain_held"] * np.abs(rigid["tension"]), tied["chain_held"] * np.abs(tied["tension"]))
    row("safety against yield (nominal and trajectory, FEM)", rigid["safety"], tied["safety"], "{:.3f}")


if __name__ == "__main__":
    main()
