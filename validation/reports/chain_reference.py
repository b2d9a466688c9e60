"""The mapped chain mesher's converged 12 x 12 stiffness of the prototype's leaf segments
against an independent reference (issue 26, "Verification"; docs/meshing.md, "Independent
reference: Q2 hexahedra (session 18)").

Segments: the [0, m1] slice of the L1 or D1 chain (end block, leaf 1, half the connector)
or [m1, s0] (half the connector, leaf 2, half a section of strut; ``segment``). Mapped:
``mapped_mesh_chain`` at ``MAPPED_NESTED`` (2 cells through, session 13's side cells, n as
given) with every cell split into r^3, condensed by
``flexcal.fem.condense.chain_stiffness`` (``benchmarks/bench_chain_convergence.py``'s nested
study). Reference: 27-node hexahedra (``flexcal.fem.reference_hex_chain``: another element
family, its own grid, geometry, assembly and end conditions) at refinement r. ``richardson``
fits rate and limit over three levels of each; the reference's uncertainty as the notch
hinges' (``hinge_reference.reference_limit``). The prototype's mesh: the segment provider's
(``segment_stiffness_fem``: ``PROTOTYPE_CHAIN_OPTIONS``, 7 asked for, mirrored condensation).
"""

from __future__ import annotations

import json
import zlib
from pathlib import Path

import numpy as np

from .hinge_reference import AGREEMENT, _cached, reference_limit

__all__ = ["AGREEMENT", "MAPPED_NESTED", "reference_chain", "segment", "mapped_stiffness", "reference_stiffness",
           "prototype_stiffness", "compare"]

NAMES = ("ux", "uy", "uz", "rx", "ry", "rz")
MAPPED_NESTED = {"n_base": 2, "options": {"side_aspect": 3.0, "slenderness": None}}
"""The nested mapped sequence of docs/meshing.md ("Convergence"): 2 through, session 13's grid."""


def reference_chain(chain_name: str):
    """The ``FlexureChain`` named ``chain_name`` ("L1", "D1", ...) of the reference mount."""
    from flexcal.geometry.params import reference_mechanism

    return {c.name: c.chain for c in reference_mechanism().chains}[chain_name]


def segment(chain_name: str, index: int = 0):
    """The prototype's ``index``-th slice of chain ``chain_name`` (``section_nodes``)."""
    from flexcal.geometry.params import ChainSegment
    from flexcal.validation.prototype.segments import section_nodes

    chain = reference_chain(chain_name)
    nodes = section_nodes(chain)
    return ChainSegment(chain=chain, x_start=float(nodes[index]), x_end=float(nodes[index + 1]))


def _condensed(part, mesh) -> np.ndarray:
    from flexcal.fem.condense import chain_stiffness
    from flexcal.geometry.exact import end_planes, reference_points
    from flexcal.geometry.params import STEEL

    planes, points = end_planes(part), reference_points(part)
    k = chain_stiffness(mesh, STEEL, planes["A"], points["A"], planes["B"], points["B"])
    return 0.5 * (k + k.T)


def mapped_stiffness(part, refinement: int, mirrored: bool = False) -> tuple[np.ndarray, int]:
    """(12 x 12 [SI], DOF) of the nested mapped level r (``MAPPED_NESTED``); ``mirrored``:
    the level's part on y >= 0, z >= 0 condensed per parity class
    (``mirrored_chain_stiffness``, as the prototype's provider; a quarter of the DOF, another
    mesh: the mirrored cells' diagonals mirrored), DOF those of the part."""
    from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain, mapped_mesh_chain_mirror_part

    options = dict(elements_through_thickness=MAPPED_NESTED["n_base"], refinement=refinement,
                   **MAPPED_NESTED["options"])
    if not mirrored:
        mesh, _ = mapped_mesh_chain(part, measure=False, **options)
        return _condensed(part, mesh), mesh.n_dof
    from flexcal.fem.condense import mirrored_chain_stiffness
    from flexcal.geometry.exact import end_planes, reference_points
    from flexcal.geometry.params import STEEL

    mesh, axes = mapped_mesh_chain_mirror_part(part, **options)
    planes, points = end_planes(part), reference_points(part)
    k = mirrored_chain_stiffness(mesh, STEEL, planes["A"], points["A"], planes["B"], points["B"], axes)
    return 0.5 * (k + k.T), mesh.n_dof


def reference_stiffness(part, refinement: int) -> tuple[np.ndarray, int]:
    from flexcal.fem.reference_hex_chain import hex27_segment_stiffness

    return hex27_segment_stiffness(part, refinement=refinement)


def prototype_stiffness(part, options: dict | None = None) -> tuple[np.ndarray, int]:
    """(12 x 12 [SI], -1) the virtual prototype's segment provider computes (its cache: FLEXCAL_CACHE_DIR);
    with ``options``, the same mirrored condensation on that grid instead of ``PROTOTYPE_CHAIN_OPTIONS``
    (a candidate grid for the prototype; 7 asked for), not cached."""
    if options is not None:
        from .chain_cuts import segment_stiffness

        return segment_stiffness(part, 7.0, options), -1
    from flexcal.validation.prototype.fem_provider import segment_stiffness_fem

    return segment_stiffness_fem(part), -1


def compare(chain_name: str, folder: Path | None, mapped_levels, ref_levels, prototype: bool = False,
            mirrored: bool = False, index: int = 0, prototype_options: dict | None = None):
    """Rows (entry, mapped rate, mapped limit, reference rate, reference limit, its
    uncertainty, (mapped limit - reference limit) / |reference limit|, (finest mapped -
    reference limit) / |reference limit|, (prototype's mesh - reference limit) / |reference
    limit| (NaN without ``prototype``), the reference's rate spread) for every dominant entry
    (``DOMINANT_FRACTION`` on the finest reference) of the upper triangle of the 12 x 12
    stiffness [SI] of chain ``chain_name``'s leaf segment ``index`` (0: [0, m1], 1: [m1, s0]).
    ``mirrored``: the mapped levels condensed on their mirror part (``mapped_stiffness``);
    ``prototype_options``: the prototype's mesh on that grid (``prototype_stiffness``)."""
    from flexcal.fem.convergence import dominant_entries, richardson
    from flexcal.validation.reports.fem import DOMINANT_FRACTION

    part = segment(chain_name, index)
    stem = f"{chain_name}_{index}"
    n_base = MAPPED_NESTED["n_base"]
    kind = "mapped_mirror" if mirrored else "mapped"
    mapped = np.array([_cached(folder, f"{kind}_{stem}_n{n_base}_r{r}", lambda r=r: mapped_stiffness(part, r, mirrored))
                       for r in mapped_levels])
    reference = np.array([_cached(folder, f"hex27_{stem}_r{r}", lambda r=r: reference_stiffness(part, r))
                          for r in ref_levels])
    proto_tag = f"prototype_{stem}" if prototype_options is None else \
        f"prototype_{stem}_{zlib.crc32(json.dumps(prototype_options, sort_keys=True).encode()):08x}"
    proto = None if not prototype else _cached(folder, proto_tag, lambda: prototype_stiffness(part, prototype_options))
    fit = richardson(1.0 / np.asarray(mapped_levels[-3:], float), mapped[-3:])
    ref_rate, ref_lim, ref_unc, ref_spread = reference_limit(ref_levels, reference)
    mask = np.triu(dominant_entries(reference[-1], DOMINANT_FRACTION))
    label = [f"{s}{node}" for node in "AB" for s in NAMES]
    rows = []
    for i, j in zip(*np.nonzero(mask)):
        scale = abs(ref_lim[i, j])
        rows.append((f"K[{label[i]},{label[j]}]", fit.rate[i, j], fit.limit[i, j], ref_rate[i, j], ref_lim[i, j],
                     ref_unc[i, j], (fit.limit[i, j] - ref_lim[i, j]) / scale,
                     (mapped[-1, i, j] - ref_lim[i, j]) / scale,
                     np.nan if proto is None else (proto[i, j] - ref_lim[i, j]) / scale, ref_spread[i, j]))
    return rows
