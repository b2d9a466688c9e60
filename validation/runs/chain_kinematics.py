"""The chains' second-order shortening measured on the virtual prototype's chains at the
nominal design, for the consistent model (``flexcal.model.consistent``, docs/model.md 10).

One chain of the prototype (its five segment superelements, FEM or analytic stiffness) with
end A clamped and end B moved by D (6-vector in the chain frame: translation, rotation
vector); the interior nodes find their equilibrium. The axial force at A is
``N(D) = k (D_x + D^T S D) + O(D^3)``: its even part at +-h along each pair of directions
gives S, its odd part along x the axial stiffness k. The model then uses
``S_elements(P) + (S(P0) - S_elements(P0))``: the shortening form of the candidate's own chain
from its elements (``flexcal.model.shortening``, equal to this probe on analytic segments to
4 digits) plus the measured correction, like the FEM compliance factors (``model_correction``).

Measured (analytic and FEM segments agree to 1 %): the driving chains' S_zz is 0.93 of
Eq. 4-5's 1/(2 L_z), their rotation entries S_ry,ry and S_rz,rz 1.8x and 6x; the load
chains' 0.99-1.0 of it. The prototype's segments measure strain as the se(3) logarithm of
their relative pose, whose axial part carries -1/2 (phi x d): that, not beam theory
(1/2 int w'^2, which the experiment found further off), is the truth's second-order kinematics.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from flexcal.geometry.params import FlexureChain
from flexcal.model.shortening import chain_shortening_form
from flexcal.model.parameters import ParameterSpace

from ..prototype.equilibrium import Loads, SolverSettings, build_assembly, solve_equilibrium
from ..prototype.kinematics import pose, se3_exp, translation_pose
from ..prototype.segments import StiffnessProvider, end_stiffness, is_tied, prepare_chains, section_nodes
from ..prototype.superelement import CoupledStiffness

__all__ = ["chain_shortening", "chain_frame_stiffness", "shortening_corrections", "consistent_space"]

TRANSLATION_STEP = 2e-4  # [m] lateral probe: S D^2 ~ 10 nm of shortening, 1e-4 of the 1e-5 N force tolerance's noise
ROTATION_STEP = 2e-3  # [rad] about 0.4x the workspace's largest rotation
# the modules of flexcal.validation whose code computes a probe: their sources are in its cache
# key (``flexcal.fem.cache.sources_digest``), beside the chain's stiffness as numbers
PROBE_CODE = ("flexcal.validation.runs.chain_kinematics", "flexcal.validation.prototype.equilibrium",
              "flexcal.validation.prototype.superelement", "flexcal.validation.prototype.kinematics",
              "flexcal.validation.prototype.segments")


def _chain_assembly(chain: FlexureChain, provider: StiffnessProvider):
    """One chain: interior nodes free (bodies 0-3), A on ground (body 4), B prescribed (body 5);
    with its ``chain_frame_stiffness``."""
    xs = section_nodes(chain)
    selection = [np.eye(6)] * 4 + [np.zeros((6, 0)), np.zeros((6, 0))]
    node_body = [4, 0, 1, 2, 3, 5]
    poses = np.broadcast_to(np.eye(4), (6, 4, 4)).copy()
    offsets = []
    for k in range(6):
        node = pose(np.eye(3), np.array([xs[k], 0.0, 0.0]))
        if k == 0:
            offsets.append(node)
        else:
            offsets.append(np.eye(4))
            poses[node_body[k]] = node
    references = [translation_pose(np.array([-(xs[s + 1] - xs[s]), 0.0, 0.0])) for s in range(5)]
    assembly = build_assembly(selection, node_body, np.array(offsets), [(s, s + 1) for s in range(5)],
                              np.array(references))
    return assembly, poses, chain_frame_stiffness(chain, provider), float(xs[-1])


def chain_frame_stiffness(chain: FlexureChain, provider: StiffnessProvider):
    """What one chain's equilibrium takes (``equilibrium.evaluate``), as the prototype's frame
    holds the chain (``mechanism.frame_stiffness``): for a provider with ``chain_stiffness(chain)``
    (the tied one, ``tied_chains.tied_fem_provider``) a one-chain ``CoupledStiffness`` of its
    K_chain (30, 30) on the five segments' twists; for any other its five segments' K_jj (5, 6, 6)
    [SI], symmetrized (rigid cuts)."""
    if is_tied(provider):
        return CoupledStiffness(blocks=np.asarray(provider.chain_stiffness(chain), dtype=float)[None],
                                segments=np.arange(5)[None])
    xs = section_nodes(chain)
    kjj = np.array([end_stiffness(np.asarray(provider(chain, float(xs[s]), float(xs[s + 1]))))
                    for s in range(5)])
    return 0.5 * (kjj + np.swapaxes(kjj, 1, 2))


def chain_shortening(chain: FlexureChain, provider: StiffnessProvider) -> tuple[np.ndarray, float]:
    """(S (6, 6) [1/m, 1, m], k [N/m]) of one chain (module docstring), chain frame at B; the
    chain as the prototype's frame holds it (``chain_frame_stiffness``: a tied provider's
    segments joined through its cut fields).

    Cached (``flexcal.fem.cache``, in the provider's cache folder): a probe is 53 equilibria of
    small-matrix Python, ~0.17 s, and the consistent model asks for 23 of them at each start of a
    command (~4 s of a warm ``flexcal verify``). The key holds what the probe reads: the chain,
    the stiffness the provider gives it (the numbers, so any provider), the steps, the solver's
    settings and the sources of ``PROBE_CODE``; a cached probe is the computed one to the bit."""
    from flexcal.fem.cache import cached, sources_digest

    assembly, poses0, frame, length = _chain_assembly(chain, provider)
    settings = SolverSettings()
    parts = {"kind": "chain_shortening_probe", "code": sources_digest(*PROBE_CODE), "chain": chain, "frame": frame,
             "steps": [TRANSLATION_STEP, ROTATION_STEP], "settings": settings}
    found = cached(parts, lambda: _probe(assembly, poses0, frame, length, settings),
                   getattr(provider, "cache_directory", None))
    return found["shortening"], float(found["stiffness"])


def _probe(assembly, poses0, frame, length: float, settings: SolverSettings) -> dict[str, np.ndarray]:
    """{"shortening": S (6, 6), "stiffness": k} of ``chain_shortening``, computed."""
    steps = np.array([TRANSLATION_STEP] * 3 + [ROTATION_STEP] * 3)

    def tension(d: np.ndarray) -> float:
        poses = poses0.copy()
        poses[5] = pose(se3_exp(np.r_[0.0, 0.0, 0.0, d[3:]])[:3, :3], np.array([length, 0.0, 0.0]) + d[:3])
        _, info = solve_equilibrium(assembly, poses, frame, Loads(), settings, where="(chain shortening probe)",
                                    final_tangent=False)  # the gradients alone are read
        return float(-info.segment_gradient[0, 0])  # the chain's pull on node A along +x

    unit = np.eye(6) * steps
    n0 = tension(np.zeros(6))
    stiffness = (tension(unit[0]) - tension(-unit[0])) / (2.0 * steps[0])
    quadratic = np.zeros((6, 6))
    for a in range(1, 6):  # the axial direction itself has no second-order shortening
        quadratic[a, a] = (tension(unit[a]) + tension(-unit[a]) - 2.0 * n0) / (2.0 * steps[a] ** 2)
        for b in range(a + 1, 6):
            both, cross = unit[a] + unit[b], unit[a] - unit[b]
            quadratic[a, b] = quadratic[b, a] = (tension(both) + tension(-both) - tension(cross) - tension(-cross)) / (
                8.0 * steps[a] * steps[b])
    return {"shortening": quadratic / stiffness, "stiffness": np.array(stiffness)}


def shortening_corrections(space: ParameterSpace, provider: StiffnessProvider) -> np.ndarray:
    """(n_chains, 6, 6): measured S minus the model's own shortening form
    (``flexcal.model.shortening.chain_shortening_form``) at the nominal chains of ``space``."""
    mech = space.mechanism
    prepare_chains(provider, [p.chain for p in mech.chains])
    done, rows = {}, []
    # each chain's own probe (not one per design, ``same_design``): sharing L1's for L2 (1 ulp
    # longer) moved the noise-free main job's discrepancy fit into another optimum (base z 0.18 ->
    # 2.27, session 25; docs/calibration.md "Session 25"), for 6 s of a cold main job
    for placement in mech.chains:
        key = placement.chain
        if key not in done:  # identical chains share their probe
            measured, _ = chain_shortening(key, provider)
            done[key] = measured - chain_shortening_form(
                key.length, key.hinge_length, key.width, key.fillet, key.thickness_1, key.thickness_2,
                section=key.section, connector_length=key.connector_length, end_block_length=key.end_block_length,
                material=mech.material)
        rows.append(done[key])
    return np.array(rows)


def consistent_space(space: ParameterSpace, provider: StiffnessProvider) -> ParameterSpace:
    """``space`` with the consistent second-order model (its measured ``chain_shortening``)."""
    corrections = shortening_corrections(space, provider)
    return dataclasses.replace(space, second_order=True, chain_shortening=tuple(float(v) for v in corrections.ravel()))
