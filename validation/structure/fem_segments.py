"""FEM chain segments for the structural checks: Guyan stiffness and mass, and the stress
fields of unit node motions, cached.

Each canonical segment (``flexcal.validation.prototype.fem_provider.canonical_segment``:
a slice in a chain's second half is the mirror image of one in its first) is built as a
CadQuery solid, meshed with quadratic tets (``flexcal.fem.mesh.mesh_part``) and reduced
onto its two section nodes with ``flexcal.fem.guyan.guyan_reduce_part``: stiffness and
consistent mass (12 x 12, chain axes) and, for each of the 12 unit node motions, the
nodal Cauchy stress (``flexcal.fem.results.nodal_stress``, float32 to keep the cache
entry at ~12 x 6 x 4 bytes per node). Stored with ``flexcal.fem.cache.cached`` under a
key of the segment, material and mesh setting, so a segment is built once.

The stress at a prototype state follows by linearity from the segment's deformation
twist xi (``superelement.segment_deformation``): node motions u = (0, xi) (start node
held, end node moved by xi in its own axes), mapped onto the canonical segment for a
mirrored one. Von Mises is invariant under the mirror's rotation.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from flexcal.geometry.params import STEEL, ChainSegment, FlexureChain, Material

from ..prototype.fem_provider import _TURN_Z, canonical_segment
from ..prototype.mechanism import N_CHAINS, N_SEGMENTS, Prototype
from ..prototype.superelement import relative_pose, segment_deformation

__all__ = ["DEFAULT_ELEMENTS_THROUGH", "segment_structure", "mirror_map", "FemSegments", "chain_peak_stress_fem"]

DEFAULT_ELEMENTS_THROUGH = 2.0
"""Quadratic tets through the thinnest leaf: ~1 % of the converged compliance (the
``flexcal chain`` default, docs/meshing.md), and half the DOFs of 3."""


def mirror_map() -> np.ndarray:
    """P (12, 12): a mirrored segment's node motions u give the canonical segment's
    P^T u (its matrices are P K P^T; ``fem_provider.mirror_segment_stiffness``)."""
    T = np.kron(np.eye(4), _TURN_Z)
    swap = np.block([[np.zeros((6, 6)), np.eye(6)], [np.eye(6), np.zeros((6, 6))]])
    return swap @ T


def _compute(segment: ChainSegment, material: Material, elements_through: float) -> dict[str, np.ndarray]:
    from flexcal.fem.guyan import guyan_reduce_part
    from flexcal.fem.mesh import mesh_part
    from flexcal.fem.results import nodal_stress
    from flexcal.geometry.solids import segment_solid

    start = time.perf_counter()
    part = segment_solid(segment)
    mesh, _ = mesh_part(part, elements_through_thickness=elements_through)
    reduced = guyan_reduce_part(mesh, material, part.end_planes["A"], part.reference_points["A"],
                                part.end_planes["B"], part.reference_points["B"])
    fields = reduced.solution.unit_motion_fields
    stress = np.stack([nodal_stress(mesh, material, fields[k]) for k in range(12)]).astype(np.float32)
    return {"stiffness": 0.5 * (reduced.stiffness + reduced.stiffness.T), "mass": reduced.mass,
            "unit_stress": stress, "nodes": np.asarray(mesh.nodes, float), "n_dof": np.array(3 * len(mesh.nodes)),
            "total_mass": np.array(reduced.total_mass), "wall_s": np.array(time.perf_counter() - start)}


def segment_structure(chain: FlexureChain, x_start: float, x_end: float, material: Material = STEEL, *,
                      elements_through: float = DEFAULT_ELEMENTS_THROUGH, cache_directory=None
                      ) -> tuple[dict[str, np.ndarray], bool]:
    """(arrays of the canonical segment, mirrored?) for the slice [x_start, x_end] [m]:
    "stiffness", "mass" (12, 12), "unit_stress" (12, n_nodes, 6) [Pa per unit motion] and
    "nodes" (n_nodes, 3) [m] (chain axes, x from the chain's end A) of the canonical segment (module docstring); built or read from the cache."""
    from flexcal.fem.cache import cached

    # the chain's length to 1 pm, like the cuts: L1-L3 are the same chain but their lengths,
    # |B - A| of rotated points, differ in the last bits, which would give three cache keys
    chain = dataclasses.replace(chain, length=round(chain.length, 12))
    segment, mirrored = canonical_segment(chain, x_start, x_end)
    # "layout" 2: the entries hold the mesh nodes too (where a peak stress sits)
    parts = {"kind": "structure_segment", "layout": 2, "segment": segment, "material": material,
             "mesh": {"elements_through_thickness": float(elements_through)}}
    return cached(parts, lambda: _compute(segment, material, elements_through), cache_directory), mirrored


class FemSegments:
    """The FEM segments of a mechanism's chains, as a stiffness provider for
    ``build_prototype`` (``provider(chain, x_start, x_end) -> (12, 12)``) and as a source
    of segment masses and stresses. ``progress``: print one line per segment built."""

    def __init__(self, material: Material = STEEL, *, elements_through: float = DEFAULT_ELEMENTS_THROUGH,
                 cache_directory=None, progress: bool = False):
        self.material, self.elements_through = material, float(elements_through)
        self.cache_directory, self.progress = cache_directory, progress
        self.description = f"FEM segments (Guyan K and M), {self.elements_through:g} elements through the leaves"
        self._memo: dict = {}  # slice -> (arrays, mirrored): the stresses ask for each slice at every state

    def _get(self, chain: FlexureChain, x_start: float, x_end: float):
        key = (chain, float(x_start), float(x_end))
        if key not in self._memo:
            self._memo[key] = self._load(chain, x_start, x_end)
        return self._memo[key]

    def _load(self, chain: FlexureChain, x_start: float, x_end: float):
        start = time.perf_counter()
        arrays, mirrored = segment_structure(chain, x_start, x_end, self.material,
                                             elements_through=self.elements_through,
                                             cache_directory=self.cache_directory)
        if self.progress and time.perf_counter() - start > 1.0:
            print(f"  segment [{x_start * 1e3:.4g}, {x_end * 1e3:.4g}] mm of a {chain.length * 1e3:.4g} mm chain: "
                  f"{int(arrays['n_dof'])} DOF, {time.perf_counter() - start:.1f} s", flush=True)
        return arrays, mirrored

    def _matrix(self, name: str, chain: FlexureChain, x_start: float, x_end: float) -> np.ndarray:
        arrays, mirrored = self._get(chain, x_start, x_end)
        P = mirror_map()
        return P @ arrays[name] @ P.T if mirrored else np.array(arrays[name])

    def __call__(self, chain: FlexureChain, x_start: float, x_end: float) -> np.ndarray:
        return self._matrix("stiffness", chain, x_start, x_end)

    def mass(self, chain: FlexureChain, x_start: float, x_end: float) -> np.ndarray:
        """Guyan mass (12, 12) [kg, kg m, kg m^2] of the slice, chain axes."""
        return self._matrix("mass", chain, x_start, x_end)

    def peak_von_mises(self, chain: FlexureChain, x_start: float, x_end: float, motion: np.ndarray) -> float:
        """Largest nodal von Mises stress [Pa] of the slice under node motions (12,) [m, rad]."""
        return self.peak_von_mises_at(chain, x_start, x_end, motion)[0]

    def peak_von_mises_at(self, chain: FlexureChain, x_start: float, x_end: float, motion: np.ndarray
                          ) -> tuple[float, np.ndarray]:
        """(largest nodal von Mises stress [Pa], where (3,) [m]: that node in chain axes)
        of the slice under node motions (12,) [m, rad]; a mirrored slice's node is turned
        back into place (x -> L - x, y -> -y)."""
        from flexcal.fem.results import von_mises

        arrays, mirrored = self._get(chain, x_start, x_end)
        u = mirror_map().T @ motion if mirrored else np.asarray(motion, float)
        stress = np.einsum("k,kni->ni", u, arrays["unit_stress"].astype(float))
        values = von_mises(stress)
        k = int(np.argmax(values))
        where = np.array(arrays["nodes"][k], float)
        if mirrored:
            where = _TURN_Z @ where + np.array([chain.length, 0.0, 0.0])
        return float(values[k]), where


def chain_peak_stress_fem(prototype: Prototype, poses: np.ndarray, segments: FemSegments) -> np.ndarray:
    """Peak nodal von Mises stress (6,) [Pa] of each chain at body ``poses`` (FEM
    segments; module docstring)."""
    from ..prototype.equilibrium import node_poses

    a = prototype.assembly
    nodes = node_poses(a, poses)
    rel = relative_pose(nodes[a.segment_nodes[:, 0]], nodes[a.segment_nodes[:, 1]])
    xi = segment_deformation(rel, a.segment_reference_inverse).reshape(N_CHAINS, N_SEGMENTS, 6)
    out = np.zeros(N_CHAINS)
    for c, placement in enumerate(prototype.mechanism.chains):
        xs = prototype.section_x[c]
        for s in range(N_SEGMENTS):
            motion = np.r_[np.zeros(6), xi[c, s]]
            out[c] = max(out[c], segments.peak_von_mises(placement.chain, xs[s], xs[s + 1], motion))
    return out
