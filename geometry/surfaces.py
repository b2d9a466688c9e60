"""The boundary of a hinge or chain solid as bounded analytic surfaces.

The boundary of every part built from the pieces of ``flexcal.geometry.exact`` is a
union of bounded analytic patches (``flexcal.geometry.patches``: axis-aligned planes,
circular cylinders; a profile may add its own curved patch), each bounded by a box;
outward normals point out of the material. Each compliant piece gives its own
(``ThinPiece.patches``); the blocks and end faces are made here. The mesher snaps
boundary nodes onto them; the tests check that the CAD solids lie on them. Pure numpy, lengths [m], part frame.
"""

from __future__ import annotations

from .exact import BoxPiece, Params, end_names, piece_label, pieces
from .patches import CylinderPatch, Patch, PlanePatch

__all__ = ["PlanePatch", "CylinderPatch", "Patch", "boundary_patches"]


def _box_patches(piece: BoxPiece, label: str) -> list[Patch]:
    hy, hz = piece.half_y, piece.half_z
    out: list[Patch] = []
    for sign in (-1, 1):
        out.append(PlanePatch(name=f"{label}:{'+' if sign > 0 else '-'}y", axis=1, value=sign * hy, sign=sign,
                              lower=(piece.x0, -hy, -hz), upper=(piece.x1, hy, hz)))
        out.append(PlanePatch(name=f"{label}:{'+' if sign > 0 else '-'}z", axis=2, value=sign * hz, sign=sign,
                              lower=(piece.x0, -hy, -hz), upper=(piece.x1, hy, hz)))
    return out


def boundary_patches(params: Params) -> tuple[Patch, ...]:
    """Every boundary surface of the part as bounded analytic patches, in the part's frame.

    The end faces come first and are named ``"end:<name>"`` with the names of
    ``end_planes`` ("fixed"/"free" for hinges, "A"/"B" for chains). Step faces where a
    block meets a narrower leaf are included (they may contain an interior region where
    the leaf is attached; that does no harm to classification by proximity).
    """
    ps = pieces(params)
    names = end_names(params)
    first, last = ps[0], ps[-1]
    hy0, hz0 = first.end_extent()
    hy1, hz1 = last.end_extent()
    out: list[Patch] = [
        PlanePatch(name=f"end:{names[0]}", axis=0, value=first.x0, sign=-1,
                   lower=(first.x0, -hy0, -hz0), upper=(first.x0, hy0, hz0)),
        PlanePatch(name=f"end:{names[1]}", axis=0, value=last.x1, sign=1,
                   lower=(last.x1, -hy1, -hz1), upper=(last.x1, hy1, hz1)),
    ]
    for i, piece in enumerate(ps):
        label = piece_label(params, i)
        if isinstance(piece, BoxPiece):
            out += _box_patches(piece, label)
            # step faces towards a thinner neighbour
            for j, x, sign in ((i - 1, piece.x0, -1), (i + 1, piece.x1, 1)):
                if 0 <= j < len(ps) and not isinstance(ps[j], BoxPiece):
                    ey, ez = ps[j].end_extent()
                    if ey < piece.half_y * (1 - 1e-12) or ez < piece.half_z * (1 - 1e-12):
                        out.append(PlanePatch(name=f"{label}:step{'-' if sign < 0 else '+'}x", axis=0, value=x,
                                              sign=sign, lower=(x, -piece.half_y, -piece.half_z),
                                              upper=(x, piece.half_y, piece.half_z)))
        else:
            out += piece.patches(label)
    return tuple(out)
