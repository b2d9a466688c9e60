"""Closed form of the corner-filleted leaf hinge (paper Fig. 5c; Lobontiu 2003)."""

from __future__ import annotations

from ..hinge import leaf_compliance
from . import ClosedForm

__all__ = ["CLOSED_FORM"]


def _compliance(hinge, material):
    return leaf_compliance(hinge.length, hinge.thickness, hinge.width, hinge.fillet, material)


def _range_warnings(hinge) -> list[str]:
    return []


CLOSED_FORM = ClosedForm(
    compliance=_compliance,
    range_warnings=_range_warnings,
    source="C_rz,Mz = 12 (l - 2a)/(E w t^3) + the right-circular formula with R = a (Lobontiu 2003: the two "
           "quarter fillets together are one circular notch); the other entries: Euler-Bernoulli/Timoshenko "
           "integrals over t(x) (model/hinge.py)",
    accuracy="FEM / closed form of C_rz,Mz: 0.97-1.05 for l 20, w 40, a 6 mm, t 2-6 mm (3 quadratic tets "
             "through the neck; docs/hinge-verification.md)",
)
