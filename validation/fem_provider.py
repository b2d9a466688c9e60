"""The virtual prototype's FEM stiffness provider: each chain segment (``ChainSegment``)
is built as a CadQuery solid, meshed with quadratic tets and condensed onto its two
section reference points (12 x 12, chain frame, SI), through the content-addressed cache
of ``flexcal.fem.cache`` so a segment solved once is never solved again.

Symmetry: a chain is mirror-symmetric about its middle; the segment [L - b, L - a] is
the segment [a, b] turned by pi about the local z axis (x -> -x, y -> -y), a proper
rotation. Its stiffness is that rotation applied to both nodes' twists, with the nodes
swapped, so only the first half of a chain (and the strut) is ever meshed.
"""

from __future__ import annotations

import sys
import time
from typing import Callable

import numpy as np

from flexcal.geometry.params import STEEL, ChainSegment, FlexureChain, Material

__all__ = ["fem_provider", "segment_stiffness_fem", "mirror_segment_stiffness", "DEFAULT_ELEMENTS_THROUGH"]

# 3 quadratic tets through the thinnest leaf section: within ~0.3 % of the converged
# bending compliance on the reference notch hinge after snapping (docs/meshing.md), at a
# third of the cost of 4.
DEFAULT_ELEMENTS_THROUGH = 3
_TURN_Z = np.diag([-1.0, -1.0, 1.0])  # rotation by pi about local z


def mirror_segment_stiffness(stiffness: np.ndarray) -> np.ndarray:
    """12 x 12 of the mirror image (turned by pi about z, nodes swapped) of a segment."""
    T = np.kron(np.eye(4), _TURN_Z)
    swap = np.block([[np.zeros((6, 6)), np.eye(6)], [np.eye(6), np.zeros((6, 6))]])
    P = swap @ T
    return P @ stiffness @ P.T


def segment_stiffness_fem(segment: ChainSegment, material: Material = STEEL, *,
                          elements_through_thickness: float = DEFAULT_ELEMENTS_THROUGH,
                          cache_directory=None) -> np.ndarray:
    """Condensed 12 x 12 stiffness [SI] of one chain segment between its end-face centres
    (node A at x_start, node B at x_end; DOF order ux, uy, uz, rx, ry, rz), cached."""
    from flexcal.fem.cache import cached

    def compute() -> dict[str, np.ndarray]:
        from flexcal.fem.condense import chain_stiffness
        from flexcal.fem.mesh import mesh_part
        from flexcal.geometry.solids import segment_solid

        part = segment_solid(segment)
        mesh, _report = mesh_part(part, elements_through_thickness=elements_through_thickness)
        (plane_a, plane_b) = (part.end_planes["A"], part.end_planes["B"])
        stiffness = chain_stiffness(mesh, material, plane_a, part.reference_points["A"], plane_b,
                                    part.reference_points["B"])
        return {"stiffness": 0.5 * (stiffness + stiffness.T)}

    parts = {"kind": "chain_segment_stiffness", "segment": segment, "material": material,
             "mesh": {"elements_through_thickness": float(elements_through_thickness)}}
    return cached(parts, compute, cache_directory)["stiffness"]


def fem_provider(material: Material = STEEL, *, elements_through_thickness: float = DEFAULT_ELEMENTS_THROUGH,
                 cache_directory=None, progress: bool = True) -> Callable[[FlexureChain, float, float], np.ndarray]:
    """A provider ``(chain, x_start, x_end) -> (12, 12)`` for ``build_prototype``."""

    def provider(chain: FlexureChain, x_start: float, x_end: float) -> np.ndarray:
        length = chain.length
        mirrored = x_start > 0.5 * length + 1e-12 and x_end > 0.5 * length
        a, b = (length - x_end, length - x_start) if mirrored else (x_start, x_end)
        # cut positions to 1 pm: L - (L - x) must find the same cache entry as x
        segment = ChainSegment(chain=chain, x_start=round(max(a, 0.0), 12), x_end=round(min(b, length), 12))
        start = time.perf_counter()
        stiffness = segment_stiffness_fem(segment, material, elements_through_thickness=elements_through_thickness,
                                          cache_directory=cache_directory)
        if progress and time.perf_counter() - start > 0.5:
            print(f"  FEM segment [{segment.x_start * 1e3:.1f}, {segment.x_end * 1e3:.1f}] mm of a "
                  f"{length * 1e3:.1f} mm chain: {time.perf_counter() - start:.1f} s", file=sys.stderr)
        return mirror_segment_stiffness(stiffness) if mirrored else stiffness

    provider.description = f"FEM (quadratic tets, {elements_through_thickness:g} through the thinnest section)"
    return provider
