"""Mass of the prototype's chain segments at their two section nodes (12 x 12).

The virtual prototype cuts each chain into five segments (``flexcal.validation.prototype.
segments``); the mount's modal model needs a mass on the same DOFs as their stiffness:
ux, uy, uz, rx, ry, rz of the start node then of the end node, chain-local axes, SI
([kg], [kg m], [kg m^2]).

``analytic_segment_mass``: what Guyan's reduction gives when the segment's flexibility
sits in its leaves: every rigid piece (end block, connector, the part of the strut next
to a leaf) follows the node on its side of the leaf's middle, as a rigid body; a leaf's
own (small) mass is split at its middle. A slice without a leaf (the strut between the
two flexures) is a uniform bar: its Guyan mass is the consistent Euler-Bernoulli mass
(``flexcal.fem.guyan.beam_consistent_mass``). Leaf volume ``w (l t + (4 - pi) a^2)``
(the flat leaf plus the four fillet corners).
"""

from __future__ import annotations

import math

import numpy as np

from flexcal.fem.guyan import beam_consistent_mass
from flexcal.fem.mass import box_inertia, rigid_body_mass
from flexcal.geometry.params import STEEL, FlexureChain, Material

__all__ = ["analytic_segment_mass", "chain_mass"]


def _piece_boxes(chain: FlexureChain, kind: str, a: float, b: float) -> tuple[float, np.ndarray]:
    """(volume [m^3], box sides (3,) [m]) of a chain piece clipped to [a, b]."""
    length = b - a
    if kind.startswith("leaf"):
        t = chain.thickness_1 if kind == "leaf1" else chain.thickness_2
        area = (chain.hinge_length * t + (4.0 - math.pi) * chain.fillet**2) * length / chain.hinge_length
        volume = chain.width * area
        thick = area / length
        sides = np.array([length, thick, chain.width]) if kind == "leaf1" else np.array([length, chain.width, thick])
        return volume, sides
    return length * chain.section**2, np.array([length, chain.section, chain.section])


def analytic_segment_mass(chain: FlexureChain, x_start: float, x_end: float, material: Material = STEEL) -> np.ndarray:
    """Mass (12, 12) of the slice ``[x_start, x_end]`` [m] of ``chain`` at its two section
    nodes (module docstring), chain-local axes, density from ``material``."""
    pieces = [(k, max(a, x_start), min(b, x_end)) for k, a, b in chain.segments()
              if min(b, x_end) - max(a, x_start) > 1e-12]
    leaves = [(a, b) for k, a, b in pieces if k.startswith("leaf")]
    if not leaves:
        return beam_consistent_mass(x_end - x_start, chain.section**2, chain.section**4 / 6.0, material.density)
    if len(leaves) > 1:
        raise ValueError(f"slice [{x_start * 1e3:.6g}, {x_end * 1e3:.6g}] mm holds {len(leaves)} leaves; the "
                         "prototype's cuts put one leaf in each flexure segment")
    split = 0.5 * sum(leaves[0])
    M = np.zeros((12, 12))
    for kind, a, b in pieces:
        parts = [(a, split), (split, b)] if kind.startswith("leaf") else [(a, b)]
        for lo, hi in parts:
            volume, sides = _piece_boxes(chain, kind, lo, hi)
            mass = material.density * volume
            centre = np.array([0.5 * (lo + hi), 0.0, 0.0])
            node = x_start if 0.5 * (lo + hi) < split else x_end
            block = slice(0, 6) if node == x_start else slice(6, 12)
            M[block, block] += rigid_body_mass(mass, box_inertia(mass, sides), centre, np.array([node, 0.0, 0.0]))
    return M


def chain_mass(chain: FlexureChain, material: Material = STEEL) -> float:
    """Mass [kg] of a whole chain (the same pieces)."""
    return float(sum(material.density * _piece_boxes(chain, k, a, b)[0] for k, a, b in chain.segments()))
