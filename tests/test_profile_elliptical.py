"""The elliptical notch hinge as one profile (geometry/fem/model profiles/elliptical.py):
closed form against quad over the exact thickness profile, the circular notch at a = b,
the exact geometry (volume, surfaces, CAD), the mapped mesh and the command line."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from flexcal.geometry.params import STEEL, CircularNotchHinge
from flexcal.geometry.profiles import hinge_type, profile_names
from flexcal.geometry.profiles.elliptical import EllipticalNotchHinge
from flexcal.model import hinge as model_hinge
from flexcal.model.profiles import closed_form_of
from flexcal.model.profiles.elliptical import elliptical_notch_compliance

from helpers import quad_hinge_entries

MM = 1e-3
REFERENCE = EllipticalNotchHinge(semi_axis_x=10 * MM, semi_axis_y=5 * MM, thickness=1 * MM, width=10 * MM,
                                 block_length=5 * MM)


def quad_matrix(hinge, material=STEEL):
    """Euler-Bernoulli/Timoshenko integrals (model/hinge.py docstring) over the geometry's
    own t(x) (``thin_piece().local_thickness``), by adaptive quad, as a 6 x 6."""
    piece = hinge.thin_piece()
    a, w = hinge.semi_axis_x, hinge.width

    def t(x):
        return float(piece.local_thickness(np.array([x]))[0])

    # the torsion formula switches long/short side where t(x) = w: split there too
    breaks = [-a, 0.0, a]
    if hinge.thickness < w < hinge.height:
        q = 1.0 - (w - hinge.thickness) / (2 * hinge.semi_axis_y)
        u = a * math.sqrt(1.0 - q * q)
        breaks = sorted(breaks + [-u, u])
    return model_hinge.entries_to_matrix(quad_hinge_entries(t, a, breaks, w, material))


CASES = [  # (a, b, t, w) [mm]
    (10.0, 5.0, 1.0, 10.0),  # the reference: a/b = 2, torsion split where t = w
    (3.0, 6.0, 0.5, 5.0),  # a < b: steep, short notch
    (20.0, 2.0, 0.3, 40.0),  # long and shallow, t/b = 0.15
]


@pytest.mark.parametrize("case", CASES)
def test_closed_form_matches_quad_over_the_exact_profile(case):
    a, b, t, w = (v * MM for v in case)
    h = EllipticalNotchHinge(semi_axis_x=a, semi_axis_y=b, thickness=t, width=w, block_length=a)
    got = closed_form_of(h).compliance(h, STEEL)
    expected = quad_matrix(h)
    nonzero = expected != 0
    # 1e-10: quad is asked for 1e-13; the circular closed forms are exact and their
    # Gauss-Legendre parts good to 4e-13 (model/hinge.py), the a/b scaling adds round-off
    np.testing.assert_allclose(got[nonzero], expected[nonzero], rtol=1e-10)
    assert np.all(got[~nonzero] == 0)


def test_a_equal_b_is_the_circular_notch():
    for radius, t, w in ((5e-3, 1e-3, 10e-3), (4e-3, 2e-3, 5e-3)):
        ellipse = elliptical_notch_compliance(radius, radius, t, w, STEEL)
        circle = model_hinge.circular_notch_compliance(radius, t, w, STEEL)
        # 1e-14: the same integrals times (a/b)^k = 1 exactly; round-off of the product only
        np.testing.assert_allclose(ellipse, circle, rtol=1e-14, atol=0)
        h = EllipticalNotchHinge(semi_axis_x=radius, semi_axis_y=radius, thickness=t, width=w, block_length=radius)
        c = CircularNotchHinge(radius=radius, thickness=t, width=w, block_length=radius)
        x = np.linspace(-radius, radius, 101)
        # 1e-15 m: two spellings of the same circle, round-off only
        np.testing.assert_allclose(h.thin_piece().local_thickness(x), c.thin_piece().local_thickness(x), atol=1e-15)


def test_registered_under_its_name_and_reached_by_every_package():
    from flexcal.fem.profiles import outline_of

    assert "elliptical" in profile_names()
    assert hinge_type("elliptical") is EllipticalNotchHinge
    outline = outline_of(REFERENCE)
    x = np.linspace(-12e-3, 12e-3, 49)
    # the mapped mesher's height is the geometry's thickness (and the block height beyond)
    np.testing.assert_allclose(outline.height(x), REFERENCE.thin_piece().local_thickness(x), rtol=1e-14)
    assert outline.block_height == pytest.approx(REFERENCE.height, rel=1e-15)  # 1e-15: the same sum t + 2b, round-off only
    # the compliance at the free face moves the notch's by the rigid block: uy/Fy grows
    at_face = model_hinge.hinge_compliance_matrix(REFERENCE, STEEL)
    assert at_face[5, 5] == pytest.approx(closed_form_of(REFERENCE).compliance(REFERENCE, STEEL)[5, 5], rel=1e-14)  # 1e-14: one formula reached by two paths (the block's rigid shift adds to uy/Fy, not rz/Mz), round-off
    assert at_face[1, 1] > closed_form_of(REFERENCE).compliance(REFERENCE, STEEL)[1, 1]


def test_exact_volume_is_the_integral_of_the_profile():
    from flexcal.geometry.exact import exact_volume

    piece = REFERENCE.thin_piece()
    notch = quad(lambda x: float(piece.local_thickness(np.array([x]))[0]), piece.x0, piece.x1, epsrel=1e-13)[0]
    blocks = 2 * REFERENCE.block_length * REFERENCE.height
    # 1e-12: quad against the closed form pi a b of the two half ellipses
    assert exact_volume(REFERENCE) == pytest.approx((notch + blocks) * REFERENCE.width, rel=1e-12)


def test_notch_patch_projects_onto_the_ellipse_and_is_the_closest_point():
    from flexcal.geometry.surfaces import boundary_patches

    notch = [p for p in boundary_patches(REFERENCE) if p.name.endswith("+ynotch")][0]
    a, b = notch.semi_axis_x, notch.semi_axis_n
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-a, a, 200), rng.uniform(0.4e-3, notch.centre[1], 200),
                              rng.uniform(-5e-3, 5e-3, 200)])
    on = notch.project(points)
    # 1e-12: Newton converged to round-off on the ellipse equation
    np.testing.assert_allclose(((on[:, 0] - notch.centre[0]) / a) ** 2 + ((on[:, 1] - notch.centre[1]) / b) ** 2,
                               1.0, atol=1e-12)  # 1e-12: round-off of the closest-point iteration on the ellipse equation
    theta = np.linspace(-np.pi, np.pi, 200001)
    dense = np.column_stack([notch.centre[0] + a * np.cos(theta), notch.centre[1] + b * np.sin(theta)])
    brute = np.array([np.min(np.hypot(*(dense - p[:2]).T)) for p in points])
    # 1e-9 m: the dense sampling's spacing (~3e-7 m) squared over the curvature radius
    np.testing.assert_allclose(notch.surface_distance(points), brute, atol=1e-9)
    # material outward normal points towards the ellipse's centre
    normal = notch.normal(on)
    assert np.all(np.einsum("ij,ij->i", normal[:, :2], np.array(notch.centre[:2]) - on[:, :2]) > 0)


def test_cad_solid_has_the_exact_volume():
    from flexcal.geometry.exact import exact_volume
    from flexcal.geometry.solids import hinge_solid

    part = hinge_solid(REFERENCE)
    # 1e-7: OpenCASCADE's volume of an exact elliptic cut (measured 1e-12); far below a
    # wrong axis (a <-> b changes it by 30 %)
    assert part.volume == pytest.approx(exact_volume(REFERENCE), rel=1e-7)


def test_mapped_mesh_follows_the_ellipse():
    from flexcal.fem.mesh_mapped import mapped_mesh_part, mapped_mesh_supported
    from flexcal.geometry.solids import hinge_solid

    assert mapped_mesh_supported(REFERENCE)
    mesh, report = mapped_mesh_part(hinge_solid(REFERENCE), elements_through_thickness=2)
    # every boundary node on the exact elliptic surface: measured 2e-18 m; a node left on
    # a chord of the arc would be ~1e-6 m off
    assert report.max_surface_deviation < 1e-12
    # measured 1.2e-4 (the circular notch's mesh of the same size: 6.7e-5); the quadratic
    # elements' error, not a wrong outline (a or b off by 1 % moves the volume by ~1e-3)
    assert abs(report.volume_error) < 2e-4


def test_mapped_mesh_at_a_equal_b_is_the_circular_notchs():
    from flexcal.fem.mesh_mapped import mapped_mesh_part
    from flexcal.geometry.solids import hinge_solid

    circle = CircularNotchHinge(radius=5 * MM, thickness=1 * MM, width=10 * MM, block_length=5 * MM)
    ellipse = EllipticalNotchHinge(semi_axis_x=5 * MM, semi_axis_y=5 * MM, thickness=1 * MM, width=10 * MM,
                                   block_length=5 * MM)
    mesh_c, _ = mapped_mesh_part(hinge_solid(circle), elements_through_thickness=2)
    mesh_e, _ = mapped_mesh_part(hinge_solid(ellipse), elements_through_thickness=2)
    np.testing.assert_array_equal(mesh_e.tets, mesh_c.tets)
    # 1e-15 m: the same points by two formulas for the same circle, round-off only
    np.testing.assert_allclose(mesh_e.nodes, mesh_c.nodes, rtol=0, atol=1e-15)


def test_command_line_builds_it_and_names_a_missing_axis():
    import argparse

    from flexcal.validation.cli.hinge import build_hinge, configure

    parser = argparse.ArgumentParser()
    configure(parser)
    args = parser.parse_args(["--type", "elliptical", "--semi-axis-x-mm", "10", "--semi-axis-y-mm", "5",
                              "--thickness-mm", "1", "--width-mm", "10", "--out", "x"])
    hinge, params = build_hinge(args)
    assert hinge == REFERENCE.__class__(semi_axis_x=10e-3, semi_axis_y=5e-3, thickness=1e-3, width=10e-3,
                                        block_length=10e-3)  # block defaults to a
    assert params == {"semi_axis_x": 10.0, "semi_axis_y": 5.0, "thickness": 1.0, "width": 10.0, "block": 10.0}
    args = parser.parse_args(["--type", "elliptical", "--semi-axis-x-mm", "10", "--thickness-mm", "1",
                              "--width-mm", "10", "--out", "x"])
    with pytest.raises(ValueError, match="--type elliptical needs --semi-axis-y-mm"):
        build_hinge(args)
