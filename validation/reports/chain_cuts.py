"""What cutting a chain into rigidly tied segments does to its stiffness (issue 26, whole
chains; docs/meshing.md, "Session 20: whole chains").

The virtual prototype builds a chain from segments (``validation/prototype/segments.py``:
[0, m1], [m1, s0], [s0, s1], [s1, m2], [m2, L]), each meshed alone and condensed onto the
centres of its two end sections with those sections rigidly tied, then joined at the
shared centres (``series_stiffness``). Three 12 x 12 of one part (a stretch of the chain,
``stretch``) between its end centres, on the mapped grid of one set of options:

- ``composed``: the part's segments each meshed and condensed alone (the prototype's way;
  at ``PROTOTYPE_CHAIN_OPTIONS`` and 7 asked for, the provider's own matrices), joined;
- ``tied``: the part meshed in one piece with grid lines at the cuts (``chain_grid``'s
  ``cuts``: along x the segments' own lines), its nodes on each cut section rigidly tied to
  the section's centre, those centres condensed out: the same mesh as ``untied`` with the
  ties, so tied - untied is what the ties do, nothing else;
- ``untied``: that one-piece mesh condensed onto its end centres only (no cut).

composed - tied is the grid's part: the one-piece grid carries every leaf's section lines
through all of its blocks, so it is finer than each segment's own.
"""

from __future__ import annotations

import numpy as np

from flexcal.validation.prototype.cut_fields import (INTERFACES, chain_order_matrices, cut_coupling, cut_orders,
                                                     interface_condensations, interface_condensed, interface_order,
                                                     interface_scale, interface_segment_stiffness, interface_segments,
                                                     joined_through_interface, mirror_part, plan_key, step_interfaces,
                                                     twist_stiffness_through_interface)

__all__ = ["stretch", "series_stiffness", "segment_stiffness", "one_piece_stiffness", "chain_segments",
           "composed_stiffness", "INTERFACES", "cut_coupling", "interface_segment_stiffness",
           "composed_interface_stiffness", "chain_order_matrices", "cut_orders",
           "twist_stiffness_through_interface", "interface_condensed", "interface_segments", "interface_order",
           "interface_condensations", "step_interfaces", "plan_key", "joined_through_interface", "interface_scale",
           "one_piece_tied_stiffness", "middle_cut", "strut_cuts", "converged_chain_estimate", "cut_rows",
           "entry_index", "mirror_part"]


def stretch(chain, n_segments: int):
    """(``ChainSegment`` [0, x_k] of ``chain`` made of its first ``n_segments`` prototype
    segments (1..5, ``section_nodes``), the x [m] of the cuts inside it)."""
    from flexcal.geometry.params import ChainSegment
    from flexcal.validation.prototype.segments import section_nodes

    nodes = section_nodes(chain)
    if not 1 <= n_segments <= len(nodes) - 1:
        raise ValueError(f"n_segments={n_segments} must be 1..{len(nodes) - 1}")
    return (ChainSegment(chain=chain, x_start=0.0, x_end=float(nodes[n_segments])),
            tuple(float(x) for x in nodes[1:n_segments]))


def series_stiffness(segments: np.ndarray) -> np.ndarray:
    """(12, 12) [SI] between the first segment's start node and the last one's end node of
    consecutive segments (n, 12, 12) (each segment's end node the next one's start node,
    DOFs ux..rz at start then end, one frame): assembled on the n + 1 nodes, the inner
    nodes condensed out (Schur complement; ``flexcal.fem.interface.series_stiffness``, which
    also joins through richer interfaces)."""
    from flexcal.fem.interface import series_stiffness as joined

    return joined(np.asarray(segments, float))


def segment_stiffness(segment, elements_through: float, options: dict, refinement: int = 1) -> np.ndarray:
    """(12, 12) [SI] of one segment meshed alone on ``options`` (every cell split into
    ``refinement``^3), condensed on its mirror part: the prototype's provider's matrix at
    ``PROTOTYPE_CHAIN_OPTIONS``, 7 asked for and refinement 1."""
    from flexcal.fem.condense import mirrored_chain_stiffness
    from flexcal.geometry.exact import end_planes
    from flexcal.geometry.params import STEEL

    mesh, axes = mirror_part(segment, elements_through, options, refinement)
    planes = end_planes(segment)
    k = mirrored_chain_stiffness(mesh, STEEL, planes["A"], planes["A"][0], planes["B"], planes["B"][0], axes)
    return 0.5 * (k + k.T)


def one_piece_stiffness(part, cuts, elements_through: float, options: dict,
                        tie_sets=None, interface: str = "rigid") -> tuple[np.ndarray, list[np.ndarray], int]:
    """(untied (12, 12), [tied (12, 12) per tie set] [SI], DOF of the meshed mirror part) of
    ``part`` meshed in one piece with grid lines at ``cuts`` [m] (module docstring),
    condensed on the mirror part (``mirrored_coupled_stiffness``). tie_sets: the cuts tied
    in each tied matrix (None: one set, every cut), each a subset of ``cuts``. interface: the
    tie (``cut_coupling``): "rigid" or a kinematic field "p<order>" on the cut face; a
    distributing one ("d-rigid", "d<order>") on the two faces of the mesh cut apart there
    (``split_at_section``), their DOFs shared."""
    from flexcal.fem.condense import mirrored_coupled_stiffness
    from flexcal.fem.coupling import RigidCoupling, select_plane_nodes
    from flexcal.fem.interface import condensed_onto_ends
    from flexcal.geometry.exact import bounding_box, end_planes
    from flexcal.geometry.params import STEEL

    cuts = tuple(float(x) for x in cuts)
    tie_sets = [cuts] if tie_sets is None else [tuple(float(x) for x in ties) for ties in tie_sets]
    if any(x not in cuts for ties in tie_sets for x in ties):
        raise ValueError(f"tie_sets={tie_sets!r} must be subsets of cuts={cuts!r}")
    mesh, axes = mirror_part(part, elements_through, {**options, "cuts": cuts})
    planes = end_planes(part)
    ends = [RigidCoupling(nodes=select_plane_nodes(mesh, planes[end]), reference_point=planes[end][0]) for end in "AB"]
    untied = mirrored_coupled_stiffness(mesh, STEEL, ends, axes)
    scale = float(bounding_box(part)[1][1])
    tied = [condensed_onto_ends(_tied_one_piece(mesh, axes, ends, sorted(ties), interface, scale))
            for ties in tie_sets]
    return 0.5 * (untied + untied.T), tied, mesh.n_dof


def one_piece_tied_stiffness(part, cuts, elements_through: float, options: dict, interface: str) -> np.ndarray:
    """(12, 12) [SI]: ``part`` meshed in one piece with grid lines at ``cuts`` [m], every cut
    tied by ``interface`` (as ``one_piece_stiffness``'s tied matrices), the cuts' DOFs
    condensed out."""
    from flexcal.fem.coupling import RigidCoupling, select_plane_nodes
    from flexcal.fem.interface import condensed_onto_ends
    from flexcal.geometry.exact import bounding_box, end_planes

    cuts = tuple(float(x) for x in cuts)
    mesh, axes = mirror_part(part, elements_through, {**options, "cuts": cuts})
    planes = end_planes(part)
    ends = [RigidCoupling(nodes=select_plane_nodes(mesh, planes[end]), reference_point=planes[end][0]) for end in "AB"]
    return condensed_onto_ends(_tied_one_piece(mesh, axes, ends, sorted(cuts), interface,
                                               float(bounding_box(part)[1][1])))


def _tied_one_piece(mesh, axes, ends, cuts, interface: str, scale: float) -> np.ndarray:
    """The one-piece mirror part condensed onto A, the cuts' interface DOFs (``cut_coupling``)
    and B, in that order; a distributing interface on the two faces of the mesh cut apart at
    each cut (``split_at_section``), their DOFs shared."""
    from flexcal.fem.condense import mirrored_coupled_stiffness
    from flexcal.fem.coupling import select_plane_nodes
    from flexcal.fem.interface import shared_interfaces, split_at_section
    from flexcal.geometry.params import STEEL

    sections = [(np.array([x, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])) for x in cuts]
    if not interface.startswith("d"):
        inner = [cut_coupling(interface, select_plane_nodes(mesh, plane), plane[0], scale) for plane in sections]
        return mirrored_coupled_stiffness(mesh, STEEL, [ends[0], *inner, ends[1]], axes)
    inner = []
    for plane in sections:
        face = select_plane_nodes(mesh, plane)
        mesh, copies = split_at_section(mesh, face, plane[0][0])
        inner += [cut_coupling(interface, face, plane[0], scale), cut_coupling(interface, copies, plane[0], scale)]
    K = mirrored_coupled_stiffness(mesh, STEEL, [ends[0], *inner, ends[1]], axes)
    sizes = [6] + [len(c.master_parity(1)) for c in inner] + [6]
    return shared_interfaces(K, sizes, [(1 + 2 * k, 2 + 2 * k) for k in range(len(sections))])


def middle_cut(chain):
    """(the whole ``chain`` as a ``ChainSegment``, (L/2,)): the chain cut once, at its middle
    (the middle of its strut), into two mirror-image halves: the cut the ties matter least at
    (docs/meshing.md, "Session 20: cutting where the ties do not matter")."""
    from flexcal.geometry.params import ChainSegment

    return ChainSegment(chain=chain, x_start=0.0, x_end=float(chain.length)), (0.5 * float(chain.length),)


def strut_cuts(chain, depth: float):
    """(the whole ``chain`` as a ``ChainSegment``, (s, L - s)): the chain cut only in its strut,
    ``depth`` [m] from either end of it (s = e + 2l + c + depth), into the leaf pair with the
    strut's first piece, the rest of the strut, and the mirror image of the first."""
    from flexcal.geometry.params import ChainSegment

    start = chain.end_block_length + 2.0 * chain.hinge_length + chain.connector_length + depth
    if not 0.0 < depth < 0.5 * chain.strut_length:
        raise ValueError(f"depth={depth} m must lie in (0, {0.5 * chain.strut_length}) m, half the strut")
    return (ChainSegment(chain=chain, x_start=0.0, x_end=float(chain.length)),
            (float(start), float(chain.length - start)))


def chain_segments(chain, n_segments: int, first_half, nodes=None) -> np.ndarray:
    """(n_segments, 12, 12) [SI] of the first ``n_segments`` prototype segments of ``chain``
    in order, ``first_half(segment)`` giving the matrix of a first-half segment and a
    second-half one taken as the mirror image of its first-half twin (``canonical_segment``).
    nodes: the section nodes [m] (None: the prototype's, ``section_nodes``)."""
    from flexcal.validation.prototype.fem_provider import canonical_segment, mirror_segment_stiffness
    from flexcal.validation.prototype.segments import section_nodes

    nodes = section_nodes(chain) if nodes is None else np.asarray(nodes, float)
    out = []
    for a, b in zip(nodes[:n_segments], nodes[1:n_segments + 1]):
        segment, mirrored = canonical_segment(chain, float(a), float(b))
        k = first_half(segment)
        out.append(mirror_segment_stiffness(k) if mirrored else k)
    return np.array(out)


def composed_stiffness(chain, n_segments: int, elements_through: float, options: dict, nodes=None) -> np.ndarray:
    """(12, 12) [SI] of the first ``n_segments`` prototype segments of ``chain`` (between
    ``nodes``, None: ``section_nodes``), each meshed alone on ``options``
    (``segment_stiffness``), joined (``series_stiffness``)."""
    return series_stiffness(chain_segments(chain, n_segments,
                                           lambda segment: segment_stiffness(segment, elements_through, options),
                                           nodes))


def composed_interface_stiffness(chain, n_segments: int, interface: str, elements_through: float, options: dict,
                                 meshes=None, nodes=None) -> np.ndarray:
    """(12, 12) [SI] of the first ``n_segments`` prototype segments of ``chain`` (between
    ``nodes``, None: ``section_nodes``), each meshed alone on ``options``, coupled at the
    cuts by ``interface`` and rigidly at the stretch's two ends, joined through the cuts'
    shared DOFs; a second-half segment is its first-half twin's condensation turned (as the
    prototype's ``mirror_segment_stiffness``). "rigid" is ``composed_stiffness``; a sequence:
    one label per cut. Polynomials in (y, z) / ``interface_scale``. meshes: {(x_start, x_end)
    rounded to 1 pm: mirror part} (None: meshed here)."""
    plan = interface_segments(chain, n_segments, nodes)
    condensed = interface_condensed(plan, interface, elements_through, options, meshes,
                                    interface_scale(chain, n_segments, nodes))
    return joined_through_interface(plan, condensed, interface)


def converged_chain_estimate(segment_limits: np.ndarray, tied: np.ndarray, untied: np.ndarray) -> np.ndarray:
    """(12, 12) [SI]: the converged stiffness of a stretch of chain in one piece, estimated
    from the converged stiffness of its rigidly tied segments (n, 12, 12), joined, less what
    the ties add (tied - untied of one one-piece mesh, ``one_piece_stiffness``)."""
    return series_stiffness(segment_limits) - (np.asarray(tied) - np.asarray(untied))


NAMES = [f"{s}{node}" for node in "AB" for s in ("ux", "uy", "uz", "rx", "ry", "rz")]


def entry_index(entry: str) -> tuple[int, int]:
    """(i, j) of an entry's name ``"K[uxA,rzB]"`` in the 12 x 12."""
    first, second = entry[2:-1].split(",")
    return NAMES.index(first), NAMES.index(second)


def cut_rows(composed: np.ndarray, tied: np.ndarray, untied: np.ndarray):
    """Rows (entry, untied value [SI], (composed - untied), (tied - untied), (composed - tied),
    each / |untied|) for the dominant entries (``DOMINANT_FRACTION`` on ``untied``) of the
    upper triangle of three 12 x 12 of one part."""
    from flexcal.fem.convergence import dominant_entries
    from flexcal.validation.reports.fem import DOMINANT_FRACTION

    mask = np.triu(dominant_entries(untied, DOMINANT_FRACTION))
    rows = []
    for i, j in zip(*np.nonzero(mask)):
        scale = abs(untied[i, j])
        rows.append((f"K[{NAMES[i]},{NAMES[j]}]", untied[i, j], (composed[i, j] - untied[i, j]) / scale,
                     (tied[i, j] - untied[i, j]) / scale, (composed[i, j] - tied[i, j]) / scale))
    return rows
