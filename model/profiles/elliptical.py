"""Closed form of the elliptical notch hinge: the circular notch's integrals, scaled.

With x = a sin(phi) the elliptical profile t(x) = t + 2b (1 - sqrt(1 - x^2/a^2)) is
t + 2b (1 - cos phi), the circular notch of radius R = b at x_c = b sin(phi); so
dx = (a/b) dx_c, and every Euler-Bernoulli integral of the ellipse is the circle's with
R = b times (a/b)^(1 + k) for the moment int x^k f(t) dx (derived here; the same reduction
that makes Smith et al. 1997, "Elliptical flexure hinges", Rev. Sci. Instrum. 68, 1474,
fall back to Paros & Weisbord at a = b). Hence C_rz,Mz = (a/b) x the Paros-Weisbord/
Lobontiu closed form at R = b, exactly, and the other entries from the same integrals
(closed forms and Gauss-Legendre of ``model.hinge.profile_integrals``).
"""

from __future__ import annotations

from ..hinge import entries_from_integrals, entries_to_matrix, profile_integrals
from . import ClosedForm

__all__ = ["CLOSED_FORM", "elliptical_notch_compliance", "ELLIPSE_MAX_T_OVER_B"]

# As the circular notch's t/R <= 1 (model/profiles/circular.py): deeper than the neck is
# thick, the slender-beam integral holds; beyond, the notch is a short thick block.
ELLIPSE_MAX_T_OVER_B = 1.0


def elliptical_notch_compliance(semi_axis_x, semi_axis_y, thickness, width, material):
    """(..., 6, 6) compliance at the free end of an elliptical notch (length 2a), fixed end
    clamped. semi_axis_x a [m], semi_axis_y b [m], thickness t [m], width w [m] broadcast."""
    scale = semi_axis_x / semi_axis_y
    circle = profile_integrals(0.0, semi_axis_y, thickness, width)
    ints = {"M0,t1": scale * circle["M0,t1"], "M0,t3": scale * circle["M0,t3"], "M0,J": scale * circle["M0,J"],
            "M2,t1": scale**3 * circle["M2,t1"], "M2,t3": scale**3 * circle["M2,t3"]}
    return entries_to_matrix(entries_from_integrals(ints, semi_axis_x, width, material.youngs_modulus,
                                                    material.poisson_ratio))


def _compliance(hinge, material):
    return elliptical_notch_compliance(hinge.semi_axis_x, hinge.semi_axis_y, hinge.thickness, hinge.width, material)


def _range_warnings(hinge) -> list[str]:
    ratio = hinge.thickness / hinge.semi_axis_y
    if ratio <= ELLIPSE_MAX_T_OVER_B:
        return []
    return [f"notch depth b={hinge.semi_axis_y * 1e3:.4g} mm with t={hinge.thickness * 1e3:.4g} mm gives "
            f"t/b={ratio:.3g}: the closed-form notch compliances hold for t/b <= {ELLIPSE_MAX_T_OVER_B:g} (as a "
            f"circular notch's t/R); beyond, the solid is a short thick block"]


CLOSED_FORM = ClosedForm(
    compliance=_compliance,
    range_warnings=_range_warnings,
    source="Euler-Bernoulli/Timoshenko integrals over the exact elliptical t(x), reduced by x = a sin(phi) to the "
           "circular notch's at R = b times powers of a/b (C_rz,Mz = (a/b) Paros-Weisbord/Lobontiu); Smith et al. "
           "1997 (Rev. Sci. Instrum. 68) for the profile",
    accuracy="FEM / closed form of C_rz,Mz: 1.05 at a/b = 0.5, 1.006 at 1, 0.973 at 2, 0.981 at 4 (t 1, b 5-10, "
             "w 10 mm; mapped mesh, 3 tets through; docs/model.md)",
)
