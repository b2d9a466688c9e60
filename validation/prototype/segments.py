"""How the prototype cuts a flexure chain into segment superelements, and an analytic
stiffness provider for them.

Cuts (docs/prototype.md): each chain is cut at rigid cross-sections into five segments
along its local x, ``[0, m1], [m1, s0], [s0, s1], [s1, m2], [m2, L]`` with

    m1 = e + l + c/2            (middle of the connector between the two leaves)
    s0 = e + 2l + c + d,  d = min(h/2, s/4)
                                (half a section width into the strut: a Saint-Venant
                                 distance from the fillet, so the cut section stays plane;
                                 a quarter of the strut if the strut is shorter than two
                                 of those, as in the 150 mm driving chains, strut 30 mm)
    s1 = L - s0,  m2 = L - m1

(e = end_block_length, l = hinge_length, c = connector_length, h = section, s =
strut_length of ``FlexureChain``). The six section nodes are ``x = 0, m1, s0, s1, m2, L``.

A **stiffness provider** is any callable ``provider(chain, x_start, x_end) -> (12, 12)``
returning the stiffness between the two section nodes of the slice ``[x_start, x_end]``
[m] of ``chain``: DOF order ``ux, uy, uz, rx, ry, rz`` of the start node then of the end
node, in the chain's local frame, SI units ([N/m], [N], [N m/rad]). The FEM provider
(CadQuery slice, condensed) plugs in here; ``analytic_provider`` below is the
development and test stand-in, built from ``flexcal.model.hinge`` (the analytic model's
beam-theory hinge compliances): the slice is a series of pieces (block, leaf 1,
connector, leaf 2, strut; partial pieces are uniform beams), composed with paper Eq. 1
``C = sum T_k C_k T_k^T`` at the end node, inverted, and expanded to 12 x 12 with the
rigid-body transfer from the start node.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from flexcal.geometry.params import STEEL, FlexureChain, Material

__all__ = [
    "StiffnessProvider",
    "sharing_segments",
    "same_design",
    "section_nodes",
    "rigid_transfer",
    "expand_end_stiffness",
    "end_stiffness",
    "rigid_mode_defect",
    "end_compliance",
    "analytic_provider",
    "chain_slices",
    "prepare_provider",
    "prepare_chains",
    "is_tied",
]

StiffnessProvider = Callable[[FlexureChain, float, float], np.ndarray]


def section_nodes(chain: FlexureChain) -> np.ndarray:
    """Local x of the six section nodes ``[0, m1, s0, s1, m2, L]`` (6,) [m] (module docstring)."""
    e, l, c, h, length = (chain.end_block_length, chain.hinge_length, chain.connector_length, chain.section,
                          chain.length)
    m1 = e + l + 0.5 * c
    s0 = e + 2.0 * l + c + min(0.5 * h, 0.25 * chain.strut_length)
    return np.array([0.0, m1, s0, length - s0, length - m1, length])


def chain_slices(chains) -> list[tuple[FlexureChain, float, float]]:
    """The distinct slices ``(chain, x_start, x_end)`` [m] between consecutive section
    nodes of ``chains`` (an iterable of ``FlexureChain``), in order: what a prototype or
    a chain compliance asks its provider for (equal chains are asked once)."""
    out: dict = {}
    for chain in chains:
        nodes = section_nodes(chain)
        for x0, x1 in zip(nodes[:-1], nodes[1:]):
            out.setdefault((chain, float(x0), float(x1)), None)
    return list(out)


def prepare_provider(provider: StiffnessProvider, slices: list[tuple[FlexureChain, float, float]]) -> None:
    """Let a provider with a ``prepare(slices)`` hook (the FEM provider's parallel build)
    compute what it will be asked for at once; a plain callable is left alone."""
    prepare = getattr(provider, "prepare", None)
    if callable(prepare):
        prepare(slices)


def is_tied(provider: StiffnessProvider) -> bool:
    """Whether ``provider`` joins a chain's segments through section fields at its cuts (it has
    ``chain_stiffness(chain)``, the K_chain on the five segments' twists: ``tied_chains.
    tied_fem_provider``, the provider fem) instead of rigidly."""
    return callable(getattr(provider, "chain_stiffness", None))


def sharing_segments(provider: StiffnessProvider) -> StiffnessProvider:
    """``provider`` for chains that share segments with each other (the model's slopes and
    curvatures: moved chains that keep some of the nominal chain's segments): a tied provider's
    ``keeping_segments()``, whose chains keep each segment condensation as a cache entry of its
    own (``tied_chains.tied_chain_matrices``, the same matrices to the bit); any other provider
    (its segments are its cache entries already) itself."""
    keeping = getattr(provider, "keeping_segments", None)
    return keeping() if callable(keeping) else provider


def prepare_chains(provider: StiffnessProvider, chains) -> None:
    """Let ``provider`` build at once what the prototype (``mechanism.build_prototype``) or a
    chain's compliance or shortening (``runs.model_correction``, ``runs.chain_kinematics``) will
    ask it for about ``chains``:
    the tied chains (its ``prepare_chains``) of a provider with ``chain_stiffness``, the
    segments (``prepare_provider``) of any other."""
    if is_tied(provider):
        build = getattr(provider, "prepare_chains", None)
        if callable(build):
            build(list(dict.fromkeys(chains)))
        return
    prepare_provider(provider, chain_slices(chains))


def same_design(chains) -> np.ndarray:
    """(n,) for each ``ChainPlacement``: the index of the first chain of the same design, its
    geometry equal but for a length within 1 pm (the reference mount's L2 is 1 ulp longer than
    L1 and L3: 4.4721359549995790e-01 against ...787e-01 m, from its mount points), so the
    model's corrections (factors, slopes, shortening) build one design once (docs/model.md 7)."""
    out = np.arange(len(chains))
    for c, placement in enumerate(chains):
        for first in range(c):
            other = chains[first].chain
            if (abs(placement.chain.length - other.length) <= 1e-12
                    and dataclasses.replace(placement.chain, length=other.length) == other):
                out[c] = first
                break
    return out


def rigid_transfer(length: float | np.ndarray) -> np.ndarray:
    """Twist transfer (..., 6, 6) from a start node to an end node ``length`` [m] further along x.

    ``[[I, -[L x]x], [0, I]]``: a rigid motion ``(u, theta)`` of the start node moves the end
    node by ``(u + theta x L x_hat, theta)``. Equals ``se3_adjoint`` of the inverse
    undeformed relative pose.
    """
    length = np.asarray(length, dtype=float)
    out = np.broadcast_to(np.eye(6), length.shape + (6, 6)).copy()
    out[..., 1, 5] = length  # u_y += L theta_z
    out[..., 2, 4] = -length  # u_z -= L theta_y
    return out


def expand_end_stiffness(end_stiffness_matrix: np.ndarray, length: float | np.ndarray) -> np.ndarray:
    """Free-free 12 x 12 stiffness (..., 12, 12) from the end-node block K_jj (..., 6, 6).

    With the deformation ``u_end - A u_start`` (A = ``rigid_transfer(length)``) the energy
    is ``1/2 u^T B^T K_jj B u``, ``B = [-A, I]``; rigid motions are its null space.
    """
    k = np.asarray(end_stiffness_matrix, dtype=float)
    a = rigid_transfer(length)
    b = np.concatenate([-a, np.broadcast_to(np.eye(6), a.shape)], axis=-1)
    return np.swapaxes(b, -1, -2) @ k @ b


def end_stiffness(stiffness_12: np.ndarray) -> np.ndarray:
    """The end-node block K_jj = K[6:, 6:] (..., 6, 6) of a 12 x 12 segment stiffness (start clamped)."""
    return np.asarray(stiffness_12, dtype=float)[..., 6:, 6:]


def rigid_mode_defect(stiffness_12: np.ndarray, length: float) -> float:
    """How far a 12 x 12 stiffness is from vanishing on rigid motions, relative [-].

    Rotations are measured as ``length * theta`` so that every entry of the scaled matrix
    is in [N/m]; the defect is ``max |K~ r~| / (max |K~| max |r~|)`` over the six rigid
    motions r. Exact providers give ~1e-12; a value above ~1e-6 means the matrix is not
    the free-free stiffness of a segment of that length.
    """
    k = np.asarray(stiffness_12, dtype=float)
    scale = np.tile(np.r_[np.ones(3), np.full(3, 1.0 / length)], 2)  # theta = (L theta) / L
    k_scaled = scale[:, None] * k * scale[None, :]
    modes = np.concatenate([np.eye(6), rigid_transfer(length)], axis=0) / scale[:, None]
    return float(np.max(np.abs(k_scaled @ modes)) / (np.max(np.abs(k_scaled)) * np.max(np.abs(modes))))


def _pieces(chain: FlexureChain, x_start: float, x_end: float) -> list[tuple[str, float, float]]:
    """The chain pieces overlapping [x_start, x_end] as (kind, a, b), clipped to it."""
    out = []
    for kind, a, b in chain.segments():
        lo, hi = max(a, x_start), min(b, x_end)
        if hi - lo > 1e-12:
            out.append((kind, lo, hi))
    return out


def end_compliance(chain: FlexureChain, x_start: float, x_end: float, material: Material = STEEL) -> np.ndarray:
    """Beam-theory compliance (6, 6) of the slice ``[x_start, x_end]`` at its end node, start clamped.

    Local chain frame; entries [m/N], [1/N], [rad/(N m)]. Leaves must lie wholly inside the
    slice (true for the cuts of ``section_nodes``); blocks, connectors and the strut may be
    cut anywhere (uniform Timoshenko beams of the square section). Uses the analytic
    model's hinge compliances (``flexcal.model.hinge``) and Eq. 1.
    """
    from flexcal.geometry.frames import rotation_about_x
    from flexcal.model.hinge import beam_compliance, leaf_compliance
    from flexcal.model.serial import serial_compliance

    if not 0.0 <= x_start < x_end <= chain.length + 1e-12:
        raise ValueError(f"slice [{x_start * 1e3:.6g}, {x_end * 1e3:.6g}] mm must satisfy "
                         f"0 <= start < end <= L = {chain.length * 1e3:.6g} mm")
    pieces, rotations, ends = [], [], []
    for kind, a, b in _pieces(chain, x_start, x_end):
        if kind in ("leaf1", "leaf2"):
            if b - a < chain.hinge_length * (1.0 - 1e-9):
                raise ValueError(f"slice [{x_start * 1e3:.6g}, {x_end * 1e3:.6g}] mm cuts through a leaf "
                                 f"hinge at [{a * 1e3:.6g}, {b * 1e3:.6g}] mm; cut in blocks or the strut")
            thickness = chain.thickness_1 if kind == "leaf1" else chain.thickness_2
            pieces.append(leaf_compliance(chain.hinge_length, thickness, chain.width, chain.fillet, material))
        else:
            pieces.append(beam_compliance(b - a, chain.section, chain.section, material))
        # leaf 2 is leaf 1 turned +90 deg about x: hinge y -> chain z
        rotations.append(rotation_about_x(0.5 * np.pi) if kind == "leaf2" else np.eye(3))
        ends.append([b, 0.0, 0.0])
    total = serial_compliance(np.array(pieces), np.array(rotations), np.array(ends), np.array([x_end, 0.0, 0.0]))
    return 0.5 * (total + total.T)


def analytic_provider(material: Material = STEEL) -> StiffnessProvider:
    """A stiffness provider (module docstring) from beam theory, for tests and development.

    Returns ``provider(chain, x_start, x_end) -> (12, 12)`` [SI]: the inverse of
    ``end_compliance`` expanded with ``expand_end_stiffness``.
    """

    def provider(chain: FlexureChain, x_start: float, x_end: float) -> np.ndarray:
        k_end = np.linalg.inv(end_compliance(chain, x_start, x_end, material))
        return expand_end_stiffness(0.5 * (k_end + k_end.T), x_end - x_start)

    provider.description = f"analytic beam-theory provider (flexcal.model.hinge), E={material.youngs_modulus:.4g} Pa"
    return provider
