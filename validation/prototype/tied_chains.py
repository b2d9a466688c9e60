"""A chain's five segments joined through section fields at its four cuts, for the virtual
prototype's frame: one 30 x 30 stiffness on the segments' deformation twists (issue 26, an
option; docs/meshing.md, "Session 24: the tied-cut frame").

The prototype's default joins its segments rigidly at the cuts m1, s0, s1, m2; that makes the
whole chains 19-23 % too stiff axially (docs/meshing.md, "Session 24: ties at every cut").
With ``ties="d12/p8"`` each segment is condensed onto order-12 distributing fields at m1, m2
and order-8 kinematic ones at s0, s1 (the strut segment [s0, s1] meshed with every cell split
into ``TIED_STRUT_REFINEMENT``^3 so its 2 x 2-cell section can carry them), the fields split
into the section bodies' rigid motions and the cuts' warping, the warping condensed
(``flexcal.fem.cut_warping``): K_chain (30, 30), cached per chain under a key with the ties.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from flexcal.geometry.params import STEEL, FlexureChain, Material

__all__ = ["TIES", "DEFAULT_TIES", "TIED_STRUT_REFINEMENT", "cut_interfaces", "tied_chain_stiffness",
           "tied_fem_provider"]

# "m/s": the interface at the mid-connector cuts m1, m2, then at the strut cuts s0, s1
# (chain_cuts.cut_coupling's labels; "d12": all four). d12/p8 and d12/d8 brought the whole
# L1 and D1 chains within 0.073 % / 0.055 % of their one piece; d12 at all four within
# 0.093 % (docs/meshing.md, "Session 24: ties at every cut")
TIES = ("d12/p8", "d12/d8", "d12")
DEFAULT_TIES = "d12/p8"
# every cell of the strut segment split into 3^3: 13 x 13 face nodes at s0, s1 (2 x 2 cells as
# meshed today cannot carry an order-8 field: its Gram matrix is singular there)
TIED_STRUT_REFINEMENT = 3
STRUT_STEP = 2  # the strut segment [s0, s1] in the chain's plan


def cut_interfaces(ties: str) -> tuple[str, str, str, str]:
    """The interface labels at the cuts (m1, s0, s1, m2) of a ``ties`` label (``TIES``)."""
    if ties not in TIES:
        raise ValueError(f"unknown ties {ties!r}: use one of {', '.join(TIES)}")
    middle, strut = ties.split("/") if "/" in ties else (ties, ties)
    return (middle, strut, strut, middle)


def _tied_chain_parts(chain: FlexureChain, ties: str, material: Material, elements_through_thickness: float) -> dict:
    """The cache key's parts of ``tied_chain_stiffness``."""
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS

    if material != STEEL:
        raise ValueError("tied chains are condensed in STEEL only (chain_cuts' condensations); use the provider fem")
    return {"kind": "tied_chain_stiffness", "chain": chain, "material": material, "ties": list(cut_interfaces(ties)),
            "mesh": {"mesher": "mapped", "elements_through_thickness": float(elements_through_thickness),
                     "options": PROTOTYPE_CHAIN_OPTIONS, "strut_refinement": TIED_STRUT_REFINEMENT,
                     "mirrored": True}}


def tied_chain_stiffness(chain: FlexureChain, ties: str = DEFAULT_TIES, material: Material = STEEL, *,
                         elements_through_thickness: float, cache_directory=None) -> np.ndarray:
    """K_chain (30, 30) [SI] of ``chain`` on its five segments' twists (module docstring),
    each segment on the prototype's grid (``PROTOTYPE_CHAIN_OPTIONS``, ``elements_through_thickness``
    asked for; the strut segment refined), cached (``flexcal.fem.cache``)."""
    from flexcal.fem.cache import cached
    from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS

    interfaces = cut_interfaces(ties)
    parts = _tied_chain_parts(chain, ties, material, elements_through_thickness)

    def compute() -> dict[str, np.ndarray]:
        from ..reports.chain_cuts import (_mirror_part, interface_condensed, interface_scale, interface_segments,
                                          plan_key, twist_stiffness_through_interface)

        plan = interface_segments(chain, 5)
        strut = plan[STRUT_STEP]
        meshes = {plan_key(strut)[:2]: _mirror_part(strut[0], elements_through_thickness, PROTOTYPE_CHAIN_OPTIONS,
                                                    TIED_STRUT_REFINEMENT)}
        scale = interface_scale(chain, 5)
        condensed = interface_condensed(plan, interfaces, elements_through_thickness, PROTOTYPE_CHAIN_OPTIONS,
                                        meshes, scale)
        return {"stiffness": twist_stiffness_through_interface(plan, condensed, interfaces, scale)}

    return cached(parts, compute, cache_directory)["stiffness"]


def tied_fem_provider(ties: str = DEFAULT_TIES, **fem_options):
    """``fem_provider(**fem_options)`` (the mapped mesher) that also gives
    ``provider.chain_stiffness(chain)``: the chain's 30 x 30 on its segments' twists, joined
    through the ``ties`` fields (``tied_chain_stiffness``), which ``build_prototype`` then uses
    in the frame, one chain after another in this process (on job threads they took as long in
    total: mapped meshing holds the interpreter lock; table1 seed 1, 2026-11-29, load ~3). Its
    12 x 12 per segment stay the rigidly tied ones (the reports and the structure assessment read
    them)."""
    from .fem_provider import DEFAULT_ELEMENTS_THROUGH, fem_provider

    cut_interfaces(ties)  # refused here if unknown
    if fem_options.get("mesher", "mapped") != "mapped":
        raise ValueError(f"ties={ties!r} need the mapped mesher (the fields' faces), not {fem_options['mesher']!r}")
    provider = fem_provider(**fem_options)
    material = fem_options.get("material", STEEL)
    through = fem_options.get("elements_through_thickness", DEFAULT_ELEMENTS_THROUGH)

    def chain_stiffness(chain: FlexureChain) -> np.ndarray:
        start = time.perf_counter()
        stiffness = tied_chain_stiffness(chain, ties, material, elements_through_thickness=through,
                                         cache_directory=fem_options.get("cache_directory"))
        if fem_options.get("progress", True) and time.perf_counter() - start > 0.5:
            print(f"  FEM tied chain ({ties}) of a {chain.length * 1e3:.1f} mm chain: "
                  f"{time.perf_counter() - start:.1f} s", file=sys.stderr)
        return stiffness

    provider.chain_stiffness, provider.ties = chain_stiffness, ties
    provider.description = provider.description[:-1] + f", cuts tied through {ties} fields)"
    return provider
