"""FEM against the closed-form hinge formulas over thin-to-thick geometries
(docs/hinge-verification.md has all six compliances of the same series).

Tolerances on the working rotation C_rz,Mz (and the coupled uy entries):
- circular notch: |FEM/closed - 1| <= 0.03 + 0.3 t/R. Converged 3-D FEM is 1.02 / 1.09 /
  1.17 x the Euler-Bernoulli integral at t/R = 0.1 / 0.25 / 0.5 (REFERENCES.md), i.e. the
  beam formula's own error grows ~0.34 t/R; 3 % covers mesh error (< 1 %) and the
  plane-strain stiffening of wider hinges. Measured: -2.6, +1.1, +3.5, +8.9, +14.2 %.
- corner-filleted leaf: 9.4 %, the largest published closed-form vs FEM disagreement
  (detasFLEX). Measured -3.4 ... +5.2 %.
"""

import pytest

from flexcal.geometry.params import STEEL, CircularNotchHinge
from flexcal.validation.reports.fem import compare_hinge
from flexcal.validation.reports.model_vs_fem import hinge_series

NOTCHES = [h for h in hinge_series() if isinstance(h, CircularNotchHinge)]
LEAVES = [h for h in hinge_series() if not isinstance(h, CircularNotchHinge)]


def _ratios(hinge):
    result = compare_hinge(hinge, STEEL, elements_through_thickness=3)
    entries = ((5, 5), (1, 1), (1, 5))  # only these: other entries are zero in closed form
    return tuple(result.compliance_fem[e] / result.compliance_analytic[e] for e in entries)


@pytest.mark.parametrize("hinge", NOTCHES, ids=lambda h: f"t/R={h.thickness / h.radius:.2f}")
def test_notch_hinges_against_closed_form(hinge):
    bound = 0.03 + 0.3 * hinge.thickness / hinge.radius
    for ratio in _ratios(hinge):
        assert abs(ratio - 1.0) <= bound, (ratio, bound)


@pytest.mark.slow
@pytest.mark.parametrize("hinge", LEAVES, ids=lambda h: f"t={h.thickness * 1e3:g}mm")
def test_leaf_hinges_against_closed_form(hinge):
    for ratio in _ratios(hinge):
        # 9.4 %: the largest published closed-form vs FEM disagreement (docstring)
        assert abs(ratio - 1.0) <= 0.094, ratio
