"""Peak stress in each chain's leaves at a prototype state, by beam theory.

Each segment carries, at its end node, the load ``g_end`` (force F, moment M; node axes
= chain-local axes) of the segment gradient (``flexcal.validation.prototype.superelement``).
At a cross-section x of the segment the part beyond x is held by the wrench
``(F, M + (x_end - x) e_x x F)``. The leaves are the only thin sections, so the peak
stress sits at a leaf's thin part: its two ends (x = leaf start + a and leaf end - a,
where the fillets begin; the moment is linear along the leaf so its extremes are there).
A leaf of thickness t (thin along local y for leaf 1, z for leaf 2) and width w gives

    sigma = |N| / (w t) + 6 |M_thin| / (w t^2) + 6 |M_wide| / (t w^2)
    tau   = |M_x| / (beta w t^2) + 1.5 max(|F_y|, |F_z|) / (w t),  beta = (1 - 0.63 t / w) / 3

and the von Mises stress sqrt(sigma^2 + 3 tau^2): the largest normal stress (at a corner)
and the largest shear stress added as if they met at one point, so an upper bound for
beam theory. The fillets' stress concentration is not in it (K_t ~ 1.1-1.2 for a / t =
1.5); the FEM path (``fem_segments``) gives the field itself.
"""

from __future__ import annotations

import numpy as np

from flexcal.geometry.params import FlexureChain

from ..prototype.mechanism import N_CHAINS, N_SEGMENTS, Prototype

__all__ = ["leaf_section_positions", "leaf_von_mises", "chain_leaf_stresses", "chain_peak_stress_beam"]


def leaf_section_positions(chain: FlexureChain) -> list[tuple[str, float]]:
    """(leaf kind, local x [m]) of the two ends of every leaf's thin part (4 leaves)."""
    out = []
    for kind, a, b in chain.segments():
        if kind.startswith("leaf"):
            out += [(kind, a + chain.fillet), (kind, b - chain.fillet)]
    return out


def leaf_von_mises(chain: FlexureChain, kind: str, force: np.ndarray, moment: np.ndarray) -> float:
    """Beam-theory von Mises bound [Pa] (module docstring) at a thin leaf section carrying
    ``force`` (3,) [N] and ``moment`` (3,) [N m] in chain-local axes."""
    t = chain.thickness_1 if kind == "leaf1" else chain.thickness_2
    w = chain.width
    thin, wide = (2, 1) if kind == "leaf1" else (1, 2)  # leaf 1 bends about z through its thickness
    sigma = abs(force[0]) / (w * t) + 6 * abs(moment[thin]) / (w * t * t) + 6 * abs(moment[wide]) / (t * w * w)
    beta = (1.0 - 0.63 * t / w) / 3.0
    tau = abs(moment[0]) / (beta * w * t * t) + 1.5 * max(abs(force[1]), abs(force[2])) / (w * t)
    return float(np.sqrt(sigma**2 + 3.0 * tau**2))


def chain_leaf_stresses(prototype: Prototype, segment_gradient: np.ndarray) -> tuple[np.ndarray, list[list[str]]]:
    """(stresses (6, 8) [Pa], labels): the von Mises bound at both ends of the thin part
    of each chain's four leaves (``leaf_section_positions`` order) at a state whose
    segment gradients are ``segment_gradient`` (n_segments, 12) [N, N m]; labels like
    "leaf 2 (B end of thin part), x = 61.50 mm"."""
    g = np.asarray(segment_gradient, float).reshape(N_CHAINS, N_SEGMENTS, 12)
    out = np.zeros((N_CHAINS, 8))
    labels = []
    for c, placement in enumerate(prototype.mechanism.chains):
        xs, names = prototype.section_x[c], []
        for k, (kind, x) in enumerate(leaf_section_positions(placement.chain)):
            s = int(np.clip(np.searchsorted(xs, x) - 1, 0, N_SEGMENTS - 1))
            force, moment = g[c, s, 6:9], g[c, s, 9:12]
            moment_x = moment + np.cross([xs[s + 1] - x, 0.0, 0.0], force)
            out[c, k] = leaf_von_mises(placement.chain, kind, force, moment_x)
            names.append(f"leaf {k // 2 + 1} ({'AB'[k % 2]} end of thin part), x = {x * 1e3:.2f} mm")
        labels.append(names)
    return out, labels


def chain_peak_stress_beam(prototype: Prototype, segment_gradient: np.ndarray) -> np.ndarray:
    """Peak von Mises bound (6,) [Pa] over the leaves of each chain at a state whose
    segment gradients are ``segment_gradient`` (n_segments, 12) [N, N m]."""
    return chain_leaf_stresses(prototype, segment_gradient)[0].max(axis=1)
