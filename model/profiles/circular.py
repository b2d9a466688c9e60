"""Closed form of the right-circular notch hinge (Paros & Weisbord 1965, Lobontiu 2003)."""

from __future__ import annotations

from ..hinge import circular_notch_compliance
from . import ClosedForm

__all__ = ["CLOSED_FORM", "NOTCH_MAX_T_OVER_R"]

# Where the Euler-Bernoulli closed form stops describing the solid notch, from FEM runs with
# the deterministic mapped mesh (3 quadratic tets through the neck, docs/reliability.md):
# FEM / closed form of the working rotation rz/Mz 1.00 at t/R = 0.2, 1.07 at 0.5, 1.12 at 1,
# 1.14 at 2 (R < t/2): past t/R = 1 the notch is a short thick block and the slender-beam
# integral is more than 10 % off.
NOTCH_MAX_T_OVER_R = 1.0


def _compliance(hinge, material):
    return circular_notch_compliance(hinge.radius, hinge.thickness, hinge.width, material)


def _range_warnings(hinge) -> list[str]:
    ratio = hinge.thickness / hinge.radius
    if ratio <= NOTCH_MAX_T_OVER_R:
        return []
    shallow = " (R < t/2: shallower than half the neck)" if ratio > 2 else ""
    return [f"notch radius R={hinge.radius * 1e3:.4g} mm with t={hinge.thickness * 1e3:.4g} mm gives "
            f"t/R={ratio:.3g}{shallow}: the closed-form notch compliances hold for t/R <= "
            f"{NOTCH_MAX_T_OVER_R:g} (R >= t); beyond, its C_rz,Mz is 10-15 % lower than the solid's (FEM)"]


CLOSED_FORM = ClosedForm(
    compliance=_compliance,
    range_warnings=_range_warnings,
    source="C_rz,Mz and C_ux,Fx: the exact right-circular formulas of Paros & Weisbord (1965) / Lobontiu (2003); "
           "the other entries: Euler-Bernoulli/Timoshenko integrals over t(x) by Gauss-Legendre (model/hinge.py)",
    accuracy="FEM / closed form of C_rz,Mz: 1.00 at t/R = 0.2, 1.07 at 0.5, 1.12 at 1, 1.14 at 2 (mapped mesh, "
             "3 tets through; docs/hinge-verification.md)",
)
