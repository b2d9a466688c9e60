"""The mapped hinge mesher's Richardson limit against an independent reference: 27-node
hexahedra on their own grid (flexcal.fem.reference_hex; issue 26 "Verification",
docs/hinge-verification.md "Independent reference (session 17)")."""

import numpy as np
import pytest

from flexcal.fem.reference_hex import _notch_profile, _stiffness, hex27_hinge_compliance, reference_grid
from flexcal.geometry.exact import exact_volume
from flexcal.geometry.params import STEEL
from flexcal.validation.cli.hinge import DEFAULT_CONFIG
from flexcal.validation.reports.hinge_reference import AGREEMENT, compare, notch

from helpers import rigid_energy_and_stretch_volume_error

DEFAULT_THROUGH = DEFAULT_CONFIG["elements_through"]  # flexcal hinge's default mesh


def test_reference_element_keeps_rigid_motions_and_linear_fields_exact():
    # isoparametric Q2: a rigid rotation stores no energy, a uniform strain the energy of
    # the meshed volume; that volume converges on the exact one as the grid is refined
    hinge = notch(1.0)
    errors = []
    for r in (1, 2, 4):
        K, nodes = _stiffness(hinge, reference_grid(hinge, 1, refinement=r), STEEL)
        rigid, volume_error = rigid_energy_and_stretch_volume_error(K, nodes, exact_volume(hinge), STEEL)
        # round-off: measured <= 2.4e-17 of the sum of the magnitudes; 1e-13 leaves 4000x
        assert rigid < 1e-13
        errors.append(volume_error)
    # measured 3.8e-4, 5.1e-5, 7.6e-6: the geometry converges at h^2.7-2.9 (nested in the arc angle)
    assert 0 < errors[2] < errors[1] / 4 < errors[0] / 16


def test_reference_profile_is_the_notch():
    # the reference writes the notch height itself; the geometry package's thin piece agrees
    hinge = notch(1.0)
    x = np.linspace(-hinge.radius, hinge.radius, 41)
    h, _ = _notch_profile(hinge, x)
    np.testing.assert_allclose(h, hinge.thin_piece().local_thickness(x), rtol=1e-12)  # two formulas, round-off
    h_out, slope_out = _notch_profile(hinge, np.array([5.5e-3, 9e-3]))
    np.testing.assert_array_equal(h_out, hinge.height)
    np.testing.assert_array_equal(slope_out, 0.0)


def test_reference_compliance_grows_under_refinement():
    # displacement FE is too stiff: the diagonal compliances grow with refinement towards the
    # limit (measured on every level r = 1..5 at 2 through; the levels' quadratic geometry is
    # not nested, so this is a measured property of these levels, not a theorem)
    hinge = notch(2.5)
    values = np.array([np.diag(hex27_hinge_compliance(hinge, n_through=2, refinement=r, aspect=2.0)[0])
                       for r in (1, 2, 3)])
    assert np.all(np.diff(values, axis=0) > 0)


ENTRIES = ["ux/Fx", "uy/Fy", "uy/Mz", "uz/Fz", "uz/My", "rx/Mx", "ry/My", "rz/Mz"]

NOTCH_LEVELS = {
    # t = 2.5 mm: mapped nested at 2 through, r = 3, 4, 5 (118k / 271k / 519k DOF); Q2 hexes at
    # 2 through, r = 3..6 (81k..614k DOF). The session-17 levels (mapped r = 2, 3, 4, hexes
    # r = 2..5) were pre-asymptotic (reference rates 1.0-1.5, two entries 0.107 % apart); from
    # r = 3 on the reference converges at 3.3-4.0 and every entry agrees within 0.029 %.
    # Measured 2026-11-28 (session 19): ~360 s CPU, 12 min wall at load ~5, 9.2 GB peak
    # (docs/hinge-verification.md, "Independent reference")
    2.5: dict(mapped_levels=(3, 4, 5), ref_levels=(3, 4, 5, 6)),
    # t = 1 mm: mapped nested at 2 through, r = 2, 3, 4 (90k / 288k / 665k DOF; rates 1.65-2.60);
    # Q2 hexes at 2 through, r = 1..4 (8.5k..459k DOF; the limit is that of r = 2, 3, 4, rates
    # 3.69-4.00, rate spread <= 0.013 %; the printed +-0.07-2.9 % is the shift from r = 1..3,
    # whose r = 1 is far off). Session 17's mapped r = 1, 2, 3 put rx/Mx at +0.122 %: its
    # 1-cell-through level was pre-asymptotic. Measured 2026-11-28 (session 22), mapped - reference
    # limit [%]: ux/Fx +0.056, uy/Fy +0.020, uy/Mz +0.018, uz/Fz +0.032, uz/My -0.037,
    # rx/Mx +0.070, ry/My +0.037, rz/Mz +0.018; default (7 through) - reference limit [%]: -0.148,
    # -0.054, -0.048, -0.177, +0.153, -0.148, -0.153, -0.048. The mapped limit is the less settled
    # side: half the spread of its limits at rates p -+ 1 is up to 0.19 % (ux/Fx, rate 1.65). 9 passed in 4 min 43 s
    # wall, 277 s CPU, 8.50 GB peak (the mapped r = 4 level; mapped r = 1, 2, 3 would stay under
    # 8 GB but is the pre-asymptotic set above), load 1.3-3.3 (docs/hinge-verification.md, "Session 22")
    1.0: dict(mapped_levels=(2, 3, 4), ref_levels=(1, 2, 3, 4)),
    # t = 0.5 mm: mapped nested at 2 through, r = 1, 2, 3 (25k / 177k / 571k DOF); Q2 hexes at
    # 2 through and 10 cells across the width, r = 2, 3, 4 (70k / 226k / 525k DOF); measured ~226 s CPU,
    # 8 min wall at load ~6, 8.7 GB peak. All eight entries agree (measured |difference| <= 0.037 %)
    0.5: dict(mapped_levels=(1, 2, 3), ref_levels=(2, 3, 4), ref_width=10),
}


@pytest.fixture(scope="module", params=sorted(NOTCH_LEVELS, reverse=True), ids=lambda t: f"t{t:g}mm")
def notch_rows(request):
    """compare's rows by entry for the notch of thickness request.param [mm] at its levels
    (NOTCH_LEVELS; both sequences at 2 cells through), with flexcal hinge's default mesh."""
    levels = NOTCH_LEVELS[request.param]
    return {row[0]: row for row in compare(request.param, None, 2, levels["mapped_levels"], 2, levels["ref_levels"],
                                           default=DEFAULT_THROUGH, ref_width=levels.get("ref_width"))}


@pytest.mark.slow
@pytest.mark.parametrize("entry", ENTRIES)
def test_mapped_limit_within_a_tenth_of_a_percent_of_the_hex27_reference(notch_rows, entry):
    assert sorted(notch_rows) == sorted(ENTRIES)  # the dominant entries: six diagonal terms, uy/Mz, uz/My
    name, _, mapped, _, reference, uncertainty, diff, *_ = notch_rows[entry]
    assert abs(diff) <= AGREEMENT, (f"{name}: mapped limit {mapped:.6e} is {100 * diff:+.3f} % from the Q2-hex "
                                    f"reference {reference:.6e} (+- {100 * uncertainty / abs(reference):.3f} %)")


DEFAULT_GOAL = 5e-3  # issue 26's goal: every dominant entry of the default mesh within 0.5 % of converged


@pytest.mark.slow
def test_the_default_hinge_mesh_is_within_half_a_percent_of_the_reference_limit(notch_rows):
    """``flexcal hinge``'s default (DEFAULT_CONFIG: 7 through; 6 missed at t = 2.5 mm, uy/Fy -0.517 %)
    against the Q2-hex limit, every dominant entry, on each of the three notches."""
    worst = max(notch_rows.values(), key=lambda row: abs(row[8]))
    assert abs(worst[8]) <= DEFAULT_GOAL, (f"{worst[0]}: the default mesh is {100 * worst[8]:+.3f} % from the Q2-hex "
                                           f"reference limit {worst[4]:.6e}")
