"""The analytic model against the FEM, entry by entry (docs/model-vs-fem.md).

Tolerances: the working bending entries (uy/Fy, uy/Mz, rz/Mz for a hinge thin in y) of
Euler-Bernoulli profile integrals agree with converged 3-D FEM within the closed forms'
published accuracy, 0.1-9.4 % (REFERENCES.md); we measured +1.0 to +2.8 %, so 5 % fails
on a real regression but not on mesh noise (~0.3 % at 3 elements through the neck).
Torsion of short wide leaves is the known large gap (St-Venant torsion with free warping
vs blocks that restrain warping): FEM is 4-5x stiffer; asserting "at least 2x stiffer"
pins the sign and size of that gap without pinning a number.
"""

import numpy as np
import pytest

from flexcal.geometry.params import STEEL, LeafHinge, reference_mechanism
from flexcal.validation.reports.fem import compare_chain, compare_hinge

WORKING = [(1, 1), (1, 5), (5, 5)]  # uy/Fy, uy/Mz, rz/Mz


def _check(result):
    fem, ana = result.compliance_fem, result.compliance_analytic
    for i, j in WORKING:
        # closed forms' published accuracy vs the measured +1.0..+2.8 % (docstring)
        assert fem[i, j] == pytest.approx(ana[i, j], rel=0.05), (i, j, fem[i, j] / ana[i, j])
    assert fem[3, 3] < 0.5 * ana[3, 3]  # torsion: FEM much stiffer (documented gap)
    # solver round-off bound as in test_fem_condense; measured 1.4e-16 (was atol 1e-6 with the default rtol 1e-7)
    np.testing.assert_allclose(fem, fem.T, rtol=0, atol=1e-8 * np.abs(fem).max())
    assert np.all(np.linalg.eigvalsh(0.5 * (fem + fem.T)) > 0)


def test_reference_leaf_hinge_against_fem():
    hinge = LeafHinge(length=20e-3, thickness=4e-3, width=40e-3, fillet=6e-3, block_length=10e-3)
    _check(compare_hinge(hinge, STEEL, elements_through_thickness=3))


@pytest.mark.slow
@pytest.mark.parametrize("index", [0, 3])  # L1-L3 share one geometry, D1-D3 another
def test_reference_chains_against_fem(index):
    _check(compare_chain(reference_mechanism().chains[index].chain, STEEL, elements_through_thickness=2))
