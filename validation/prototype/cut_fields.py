"""A chain's prototype segments joined through section fields at their cuts (issue 26).

The prototype cuts each chain at m1, s0, s1 and m2 (``segments.section_nodes``). Joined
rigidly there, the whole chains are 19-23 % too stiff axially; joined through polynomial
("p<p>") or distributing ("d<p>") fields of the cut sections (``flexcal.fem.interface``)
they come within 0.02-0.11 % of the uncut chain (docs/meshing.md, "Session 24: ties at
every cut"). This module is the plan of such a join and its pieces: which segments are
meshed (a second-half segment is its first-half twin, turned), each one's condensation onto
its end sections, the matrices in chain order, the 12 x 12 of the joined stretch and the
30 x 30 on the segments' twists the tied frame uses (``tied_chains``). The measurements
of the cuts (``validation.reports.chain_cuts``) and the tied prototype share it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["INTERFACES", "mirror_part", "cut_coupling", "interface_segment_stiffness", "segment_couplings", "interface_order",
           "interface_segments", "interface_condensations", "step_interfaces", "plan_key", "chain_order_matrices",
           "cut_orders", "joined_through_interface", "twist_stiffness_through_interface", "interface_scale",
           "interface_condensation_parts", "interface_condensed"]


def mirror_part(part, elements_through: float, options: dict, refinement: int = 1):
    """The mirror part of ``part`` on the mapped grid (``mapped_mesh_chain_mirror_part``: the
    mesh and its mirror axes), ``elements_through`` asked for, ``options`` and ``refinement``."""
    from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain_mirror_part

    return mapped_mesh_chain_mirror_part(part, elements_through_thickness=elements_through, refinement=refinement,
                                         **options)


INTERFACES = ("rigid", "p1", "p2", "p3", "p4", "d-rigid", "d1", "d2", "d3")
"""The interfaces at a cut (``flexcal.fem.interface``; docs/meshing.md, session 23): the rigid
tie, kinematic polynomial fields of order p ("p1".."p4", any "p<p>"), and distributing
couplings on the rigid motions ("d-rigid") or on fields of order p ("d1".."d3", any "d<p>")."""


def cut_coupling(interface: str, face_nodes: np.ndarray, centre: np.ndarray, scale: float):
    """The coupling of a cut face's nodes (n_s,) to its centre (3,) [m] for the ``interface``
    label (``INTERFACES``), polynomials in (y, z) / ``scale`` [m]."""
    from flexcal.fem.coupling import RigidCoupling
    from flexcal.fem.interface import RIGID, DistributingCoupling, PolynomialCoupling

    if interface == "rigid":
        return RigidCoupling(nodes=face_nodes, reference_point=centre)
    if interface.startswith("p") and interface[1:].isdigit():
        return PolynomialCoupling(nodes=face_nodes, reference_point=centre, order=int(interface[1:]), scale=scale)
    if interface == "d-rigid" or (interface.startswith("d") and interface[1:].isdigit()):
        order = RIGID if interface == "d-rigid" else int(interface[1:])
        return DistributingCoupling(nodes=face_nodes, reference_point=centre, order=order, scale=scale)
    raise ValueError(f"unknown interface {interface!r}; choose one of {', '.join(INTERFACES)}")


def interface_segment_stiffness(segment, mesh_and_axes, starts_at_cut: bool, ends_at_cut: bool, interface: str,
                                scale: float) -> np.ndarray:
    """(n_A + n_B, n_A + n_B) [SI] of one ``segment`` (as meshed: a first-half one) on its
    meshed mirror part ``mesh_and_axes`` (``mapped_mesh_chain_mirror_part``), condensed onto its
    end sections (``segment_couplings``)."""
    from flexcal.fem.condense import mirrored_coupled_stiffness
    from flexcal.geometry.params import STEEL

    mesh, axes = mesh_and_axes
    k = mirrored_coupled_stiffness(mesh, STEEL, segment_couplings(segment, mesh, starts_at_cut, ends_at_cut, interface,
                                                                  scale), axes)
    return 0.5 * (k + k.T)


def segment_couplings(segment, mesh, starts_at_cut: bool, ends_at_cut: bool, interface, scale: float) -> list:
    """The couplings of a ``segment``'s meshed mirror part at its end sections: a cut one by
    ``interface`` (``cut_coupling``; a pair: the start's, the end's), a chain end rigidly (6
    DOFs, as the prototype's)."""
    from flexcal.fem.coupling import RigidCoupling, select_plane_nodes
    from flexcal.geometry.exact import end_planes

    planes = end_planes(segment)
    labels = (interface, interface) if isinstance(interface, str) else tuple(interface)
    couplings = []
    for end, at_cut, label in (("A", starts_at_cut, labels[0]), ("B", ends_at_cut, labels[1])):
        nodes, centre = select_plane_nodes(mesh, planes[end]), planes[end][0]
        couplings.append(cut_coupling(label, nodes, centre, scale) if at_cut
                         else RigidCoupling(nodes=nodes, reference_point=centre))
    return couplings


def interface_order(interface: str):
    """The section field's order of an ``interface`` label (``INTERFACES``): ``RIGID`` for
    "rigid" and "d-rigid", p for "p<p>" and "d<p>"."""
    from flexcal.fem.interface import RIGID

    if interface in ("rigid", "d-rigid"):
        return RIGID
    if interface[:1] in ("p", "d") and interface[1:].isdigit():
        return int(interface[1:])
    raise ValueError(f"unknown interface {interface!r}; choose one of {', '.join(INTERFACES)}")


def interface_segments(chain, n_segments: int, nodes=None) -> list:
    """The first ``n_segments`` prototype segments of ``chain`` (between ``nodes`` [m], None:
    ``section_nodes``) in order, each as (the segment meshed (``canonical_segment``: a
    second-half one's first-half twin), mirrored?, the meshed segment's start is a cut?, its
    end is a cut?). A mirrored segment's start is its twin's end, so the twin's cut ends are
    the real segment's swapped; the stretch's two ends are not cuts."""
    from .fem_provider import canonical_segment
    from .segments import section_nodes

    nodes = section_nodes(chain) if nodes is None else np.asarray(nodes, float)
    out = []
    for k, (a, b) in enumerate(zip(nodes[:n_segments], nodes[1:n_segments + 1])):
        segment, mirrored = canonical_segment(chain, float(a), float(b))
        starts, ends = k > 0, k < n_segments - 1
        out.append((segment, mirrored, *((ends, starts) if mirrored else (starts, ends))))
    return out


def interface_condensations(plan, interface) -> dict:
    """{key: (segment, starts at a cut, ends at a cut, (label at its start, at its end))}: the
    distinct condensations of an ``interface_segments`` plan (a second-half segment is its
    twin's condensation, turned), key as ``plan_key``. interface: one label for every cut, or
    one per cut in the chain's order (``step_interfaces``)."""
    return {plan_key(step, labels): (step[0], step[2], step[3], labels)
            for step, labels in zip(plan, step_interfaces(plan, interface))}


def step_interfaces(plan, interface) -> list[tuple]:
    """Per step of ``plan``, (label at the meshed segment's start, at its end) (None: a chain
    end): ``interface`` one label for every cut or a sequence, one per cut in chain order; a
    mirrored step's meshed start is its end."""
    n_cuts = len(plan) - 1
    labels = [interface] * n_cuts if isinstance(interface, str) else list(interface)
    if len(labels) != n_cuts:
        raise ValueError(f"{len(labels)} interfaces for {n_cuts} cuts")
    out = []
    for k, (_, mirrored, _, _) in enumerate(plan):
        start, end = (labels[k - 1] if k > 0 else None), (labels[k] if k < n_cuts else None)
        out.append((end, start) if mirrored else (start, end))
    return out


def plan_key(step, labels=(None, None)) -> tuple:
    """The key of one ``interface_segments`` step's condensation with ``labels`` at its ends."""
    segment, _, starts, ends = step
    return (round(segment.x_start, 12), round(segment.x_end, 12), bool(starts), bool(ends), *labels)


def chain_order_matrices(plan, condensed: dict, interface) -> list[np.ndarray]:
    """The segments' matrices of ``plan`` (``interface_segments``) in chain order, each on its
    start section's DOFs then its end section's, chain frame: ``condensed`` the meshed segments'
    matrices by ``plan_key`` (``interface_segment_stiffness``), a mirrored one turned
    (``turned_segment_stiffness``: its cut fields' DOFs change sign by ``section_turn_signs``).
    interface: one label or one per cut (``step_interfaces``)."""
    from flexcal.fem.interface import RIGID, turned_segment_stiffness

    matrices = []
    for step, labels in zip(plan, step_interfaces(plan, interface)):
        k = condensed[plan_key(step, labels)]
        if step[1]:
            start, end = (RIGID if label is None else interface_order(label) for label in labels)
            k = turned_segment_stiffness(k, start, end)
        matrices.append(k)
    return matrices


def cut_orders(plan, interface) -> list:
    """The section field's order (``interface_order``) at each cut of ``plan``, in chain order."""
    n_cuts = len(plan) - 1
    labels = [interface] * n_cuts if isinstance(interface, str) else list(interface)
    return [interface_order(label) for label in labels]


def joined_through_interface(plan, condensed: dict, interface) -> np.ndarray:
    """(12, 12) [SI]: the segments of ``plan`` (``interface_segments``) joined through their
    cuts' shared ``interface`` DOFs (one label or one per cut, ``step_interfaces``;
    ``flexcal.fem.interface.series_stiffness``), ``condensed`` the meshed segments' matrices by
    ``plan_key`` (``chain_order_matrices``)."""
    from flexcal.fem.interface import series_stiffness as joined

    return joined(chain_order_matrices(plan, condensed, interface))


def twist_stiffness_through_interface(plan, condensed: dict, interface, scale: float) -> np.ndarray:
    """(6 n, 6 n) [SI]: the n segments of ``plan`` joined through their cuts' ``interface``
    fields as one stiffness on their deformation twists, every cut's warping condensed out
    (``flexcal.fem.cut_warping.chain_twist_stiffness``; arguments as ``joined_through_interface``,
    scale [m] the fields' length, ``interface_scale``)."""
    from flexcal.fem.cut_warping import chain_twist_stiffness

    return chain_twist_stiffness(chain_order_matrices(plan, condensed, interface), cut_orders(plan, interface), scale)


def interface_scale(chain, n_segments: int, nodes=None) -> float:
    """[m] the length the section fields' coordinates are divided by: the stretch's
    half-extent along y (the chains' square section: 25 mm on L1 and D1)."""
    from flexcal.geometry.exact import bounding_box
    from flexcal.geometry.params import ChainSegment

    from .segments import section_nodes

    nodes = section_nodes(chain) if nodes is None else nodes
    part = ChainSegment(chain=chain, x_start=float(nodes[0]), x_end=float(nodes[n_segments]))
    return float(bounding_box(part)[1][1])


# the modules of flexcal.validation whose code computes an interface condensation's cache entry
# (its key's "code", as ``fem_provider.SEGMENT_CODE``)
CONDENSATION_CODE = ("flexcal.validation.prototype.cut_fields", "flexcal.validation.prototype.fem_provider",
                     "flexcal.validation.prototype.segments")


def interface_condensation_parts(segment, starts_at_cut: bool, ends_at_cut: bool, labels: tuple, scale: float,
                                 elements_through: float, options: dict) -> dict:
    """The FEM cache key's parts of one condensation of ``interface_condensed`` (``cache``):
    the meshed ``segment``'s solid as its pieces (``flexcal.geometry.exact.pieces``: all its
    mapped mesh and end faces are made of) and its chain's length, so that a slice a dimension
    leaves as it was has the key of the nominal chain's exactly where
    ``runs.model_correction.unchanged_slices`` shares it (same length, same nodes, same pieces;
    the chain's other dimensions are not in it); which ends are cuts, their ``labels``, the
    fields' ``scale`` [m], the grid (``elements_through``, ``options``: the mirror part of the
    mapped grid) and the material (STEEL, ``interface_segment_stiffness``'s). The length keeps
    apart the reference mount's L2, 1 ulp longer than L1 and the same pieces: its own chain is
    built for the consistent model's shortening probe, whose round-off moves the noise-free
    discrepancy fit (docs/calibration.md, "Session 25"; docs/scale.md, "Issue 26, session 26")."""
    from flexcal.fem.cache import sources_digest
    from flexcal.geometry.exact import pieces
    from flexcal.geometry.params import STEEL

    return {"kind": "interface_segment_stiffness", "code": sources_digest(*CONDENSATION_CODE),
            "pieces": pieces(segment), "chain_length": segment.chain.length, "material": STEEL,
            "cut_ends": [bool(starts_at_cut), bool(ends_at_cut)], "labels": list(labels), "scale": float(scale),
            "mesh": {"mesher": "mapped", "elements_through_thickness": float(elements_through), "options": options,
                     "mirrored": True}}


def interface_condensed(plan, interface, elements_through: float, options: dict, meshes=None,
                        scale: float = 1.0, *, cache: bool = False, cache_directory=None) -> dict:
    """{``plan_key``: matrix}: the distinct condensations (``interface_condensations``) of
    ``plan``'s meshed segments (``interface_segment_stiffness``, fields' length ``scale``
    [m]), each on its mesh in ``meshes`` ({(x_start, x_end) rounded to 1 pm: mirror part};
    one missing is meshed on ``options`` with ``elements_through`` asked for).

    cache: each condensation from the FEM cache (``flexcal.fem.cache.cached`` in
    ``cache_directory``) under ``interface_condensation_parts``, computed and stored if missing,
    so another chain with the same segment (the slopes' moved chains, ``tied_chains``) reads it;
    only with ``meshes`` None (the key names the grid they are meshed on)."""
    from flexcal.fem.cache import cached

    if cache and meshes:
        raise ValueError("cached condensations are meshed on options: pass meshes=None with cache=True")
    meshes = {} if meshes is None else meshes
    condensed = {}
    for key, (segment, starts, ends, labels) in interface_condensations(plan, interface).items():
        def compute(segment=segment, starts=starts, ends=ends, labels=labels, key=key):
            mesh = meshes.get(key[:2]) or mirror_part(segment, elements_through, options)
            return {"stiffness": interface_segment_stiffness(segment, mesh, starts, ends, labels, scale)}

        if cache:
            parts = interface_condensation_parts(segment, starts, ends, labels, scale, elements_through, options)
            condensed[key] = cached(parts, compute, cache_directory)["stiffness"]
        else:
            condensed[key] = compute()["stiffness"]
    return condensed
