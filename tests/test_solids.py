"""CadQuery solids: volume, extent, end faces and exports checked against closed forms."""

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flexcal.geometry.exact import exact_volume, thin_sections
from flexcal.geometry.surfaces import boundary_patches
from flexcal.geometry.params import CircularNotchHinge, FlexureChain, LeafHinge, reference_mechanism

cq = pytest.importorskip("cadquery")

from flexcal.geometry.export import export_step, export_stl, import_step  # noqa: E402
from flexcal.geometry.solids import chain_solid, hinge_solid, mechanism_assembly  # noqa: E402

# OpenCASCADE integrates planes and cylinders to round-off (observed <= 1e-15 relative);
# 1e-9 leaves room for other OCC builds and still catches any wrong dimension
VOLUME_RTOL = 1e-9
# OCC bounding boxes are enlarged by the shape tolerance (1e-7 model units = 0.1 um)
BOX_ATOL = 1e-6

NOTCH = CircularNotchHinge(radius=5e-3, thickness=1e-3, width=10e-3, block_length=5e-3)
LEAF = LeafHinge(length=20e-3, thickness=4e-3, width=40e-3, fillet=6e-3, block_length=10e-3)
DRIVING = FlexureChain(length=0.150, thickness_1=0.003, thickness_2=0.003)


def notch_volume(h: CircularNotchHinge) -> float:
    """Block (2R + 2 block) x (t + 2R) x b minus two half discs pi R^2 / 2."""
    return h.width * ((2 * h.radius + 2 * h.block_length) * (h.thickness + 2 * h.radius) - math.pi * h.radius**2)


def leaf_area(length: float, t: float, a: float) -> float:
    """Leaf l x t plus four corners a^2 (1 - pi/4) left outside the quarter-circle fillets."""
    return length * t + 4 * a * a * (1 - math.pi / 4)


def leaf_volume(h: LeafHinge) -> float:
    return h.width * (2 * h.block_length * h.height + leaf_area(h.length, h.thickness, h.fillet))


def chain_volume(c: FlexureChain) -> float:
    rigid = (2 * c.end_block_length + 2 * c.connector_length + c.strut_length) * c.section**2
    leaves = 2 * c.width * (leaf_area(c.hinge_length, c.thickness_1, c.fillet)
                            + leaf_area(c.hinge_length, c.thickness_2, c.fillet))
    return rigid + leaves


LEAF_VARIANTS = [
    LEAF,
    LeafHinge(length=20e-3, thickness=4e-3, width=40e-3, fillet=6e-3, block_length=10e-3, block_height=30e-3),
    LeafHinge(length=20e-3, thickness=4e-3, width=40e-3, fillet=0.0, block_length=10e-3, block_height=10e-3),
    LeafHinge(length=20e-3, thickness=4e-3, width=40e-3, fillet=10e-3, block_length=10e-3),
]


def test_notch_hinge_volume_box_and_ends():
    part = hinge_solid(NOTCH)
    assert part.volume == pytest.approx(notch_volume(NOTCH), rel=VOLUME_RTOL)
    # two closed forms of the same volume: round-off only
    assert exact_volume(NOTCH) == pytest.approx(notch_volume(NOTCH), rel=1e-14)
    box = part.shape.BoundingBox()
    half = [NOTCH.total_length / 2, NOTCH.height / 2, NOTCH.width / 2]
    np.testing.assert_allclose([box.xmin, box.ymin, box.zmin], np.negative(half), atol=BOX_ATOL)
    np.testing.assert_allclose([box.xmax, box.ymax, box.zmax], half, atol=BOX_ATOL)
    # computed from the parameters: round-off (1 ulp of 10 mm = 1.7e-18 m)
    np.testing.assert_allclose(part.reference_points["fixed"], [-NOTCH.total_length / 2, 0, 0], atol=1e-15)
    np.testing.assert_allclose(part.reference_points["free"], [NOTCH.total_length / 2, 0, 0], atol=1e-15)  # as above
    # the thinnest section of the CAD solid is t: the solid holds (0, +-t/2) but not beyond
    for y, inside in ((0.499e-3, True), (0.501e-3, False)):
        assert part.shape.isInside(cq.Vector(0.0, y, 0.0), 1e-9) is inside


@pytest.mark.parametrize("hinge", LEAF_VARIANTS, ids=["reference", "tall_blocks", "no_fillet", "fillets_meet"])
def test_leaf_hinge_volume_and_box(hinge):
    part = hinge_solid(hinge)
    assert part.volume == pytest.approx(leaf_volume(hinge), rel=VOLUME_RTOL)
    box = part.shape.BoundingBox()
    np.testing.assert_allclose([box.xmax - box.xmin, box.ymax - box.ymin, box.zmax - box.zmin],
                               [hinge.total_length, hinge.height, hinge.width], atol=BOX_ATOL)


@settings(max_examples=12, deadline=None)
@given(t=st.floats(0.5e-3, 5e-3), a_frac=st.floats(0.0, 0.5), length=st.floats(5e-3, 30e-3),
       extra=st.floats(0.0, 10e-3))
def test_leaf_volume_property(t, a_frac, length, extra):
    """Any valid leaf hinge: CAD volume = closed form (fillets and blocks of any height)."""
    a = a_frac * length
    if 0 < a < 2e-6 or 0 < length - 2 * a < 2e-6 or 0 < extra < 2e-6:
        return  # features below the CAD kernel's resolution are rejected (tested below)
    hinge = LeafHinge(length=length, thickness=t, width=8e-3, fillet=a, block_length=3e-3,
                      block_height=t + 2 * a + extra)
    assert hinge_solid(hinge).volume == pytest.approx(leaf_volume(hinge), rel=VOLUME_RTOL)


def test_chain_volume_box_and_ends():
    for chain in (DRIVING, reference_mechanism().chains[0].chain):
        part = chain_solid(chain)
        assert part.volume == pytest.approx(chain_volume(chain), rel=VOLUME_RTOL)
        box = part.shape.BoundingBox()
        np.testing.assert_allclose([box.xmin, box.ymin, box.zmin], [0, -chain.section / 2, -chain.section / 2],
                                   atol=BOX_ATOL)
        np.testing.assert_allclose([box.xmax, box.ymax, box.zmax], [chain.length, chain.section / 2,
                                                                    chain.section / 2], atol=BOX_ATOL)
        # computed from the parameters: round-off (1 ulp of 0.15 m = 2.8e-17 m)
        np.testing.assert_allclose(part.reference_points["A"], [0, 0, 0], atol=1e-15)
        np.testing.assert_allclose(part.reference_points["B"], [chain.length, 0, 0], atol=1e-15)  # as above


def test_chain_leaves_are_thin_in_the_right_direction():
    """Leaf 1 (first after block A) is thin in y, leaf 2 thin in z (params module doc)."""
    part = chain_solid(DRIVING)
    (_, x0, x1), (_, x2, x3) = DRIVING.segments()[1], DRIVING.segments()[3]
    leaf1_mid, leaf2_mid = (x0 + x1) / 2, (x2 + x3) / 2
    t = DRIVING.thickness_1
    assert part.shape.isInside(cq.Vector(leaf1_mid, 0.49 * t, 0.4 * DRIVING.width), 1e-9)
    assert not part.shape.isInside(cq.Vector(leaf1_mid, 0.51 * t, 0.0), 1e-9)
    assert part.shape.isInside(cq.Vector(leaf2_mid, 0.4 * DRIVING.width, 0.49 * t), 1e-9)
    assert not part.shape.isInside(cq.Vector(leaf2_mid, 0.0, 0.51 * t), 1e-9)


@pytest.mark.parametrize("params", [NOTCH, LEAF, LEAF_VARIANTS[1], DRIVING], ids=["notch", "leaf", "tall", "chain"])
def test_end_planes_are_faces_of_the_solid(params):
    part = hinge_solid(params) if not isinstance(params, FlexureChain) else chain_solid(params)
    for name, (point, normal) in part.end_planes.items():
        matches = [f for f in part.shape.Faces()  # as above, for the unit normal
                   if f.geomType() == "PLANE"
                   # OCC face centre/normal: round-off (~1e-17 m); 1e-12 is far below any feature
                   and np.allclose(f.Center().toTuple(), point, atol=1e-12)
                   # (the same for the unit normal)
                   and np.allclose(f.normalAt().toTuple(), normal, atol=1e-12)]
        assert len(matches) == 1, name
        np.testing.assert_allclose(part.reference_points[name], point)


@pytest.mark.parametrize("params", [NOTCH, LEAF, LEAF_VARIANTS[1], DRIVING], ids=["notch", "leaf", "tall", "chain"])
def test_exact_surfaces_describe_the_cad_solid(params):
    """Every vertex of a fine CAD triangulation lies on one of the analytic patches the
    mesher snaps to, and every face centre too (to the chord error)."""
    part = hinge_solid(params) if not isinstance(params, FlexureChain) else chain_solid(params)
    vertices, triangles = part.shape.copy().tessellate(1e-4, 0.2)  # deflection 1e-4 x edge size
    v = np.array([p.toTuple() for p in vertices])
    centres = v[np.array(triangles)].mean(axis=1)
    patches = boundary_patches(params)
    on_surface = np.min([p.distance(v) for p in patches], axis=0)
    assert on_surface.max() < 1e-12  # vertices of the triangulation are points of the B-rep
    to_centres = np.min([p.distance(centres) for p in patches], axis=0)
    # a triangle centre is within the chord deviation of the curved faces: at most
    # 1e-4 x the longest curved edge (a fillet or notch arc, < 20 mm here) = 2 um
    assert to_centres.max() < 2e-6


def test_thin_sections_match_the_parameters():
    (notch,) = thin_sections(NOTCH)
    x = np.array([0.0, 2e-3, 5e-3])
    expected = NOTCH.thickness + 2 * NOTCH.radius - 2 * np.sqrt(NOTCH.radius**2 - x**2)
    # the same closed form (circular notch profile): round-off only
    np.testing.assert_allclose(notch.thickness(x), expected, rtol=1e-14)
    leaves = thin_sections(DRIVING)
    assert [s.thin_axis for s in leaves] == [1, 2, 2, 1]
    assert all(s.neck_thickness == 0.003 for s in leaves)


def test_step_round_trip_keeps_volume_and_declares_millimetres(tmp_path):
    part = hinge_solid(NOTCH)
    path = export_step(part, tmp_path / "notch.step")
    assert path.exists()
    text = path.read_text(errors="replace")
    assert ".MILLI." in text  # the file says mm
    back = import_step(path)
    assert back.Volume() == pytest.approx(part.volume, rel=VOLUME_RTOL)  # read back into metres
    box = back.BoundingBox()
    assert box.xmax == pytest.approx(NOTCH.total_length / 2, abs=BOX_ATOL)
    assert [p.name for p in tmp_path.iterdir()] == ["notch.step"]  # no temporary file left


def _read_binary_stl(path) -> np.ndarray:
    data = path.read_bytes()
    (count,) = struct.unpack("<I", data[80:84])
    records = np.frombuffer(data[84:84 + 50 * count], dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)),
                                                                      ("attr", "<u2")]))
    return records["v"].astype(float)


def test_stl_export_in_millimetres_within_tolerance(tmp_path):
    part = hinge_solid(NOTCH)
    tolerance = 2e-5
    path = export_stl(part, tmp_path / "notch.stl", tolerance=tolerance)
    triangles = _read_binary_stl(path) / 1e3  # file is in mm
    volume = np.einsum("ij,ij->i", triangles[:, 0], np.cross(triangles[:, 1], triangles[:, 2])).sum() / 6
    # chords deviate from the surface by at most `tolerance` (float32 adds ~1e-7 relative)
    assert abs(volume - part.volume) <= tolerance * part.shape.Area()
    np.testing.assert_allclose(triangles.reshape(-1, 3).max(axis=0),
                               # vertices are B-rep corners; float32 in the file: 6e-8 relative
                               [NOTCH.total_length / 2, NOTCH.height / 2, NOTCH.width / 2], rtol=1e-6)
    with pytest.raises(ValueError, match="tolerance"):
        export_stl(part, tmp_path / "bad.stl", tolerance=0.0)


def test_export_to_missing_folder_says_so(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        export_step(hinge_solid(NOTCH), tmp_path / "missing" / "notch.step")


def test_mechanism_assembly_places_every_chain(tmp_path):
    mech = reference_mechanism()
    assembly = mechanism_assembly(mech)
    children = {child.name: child for child in assembly.children}
    assert sorted(children) == sorted(c.name for c in mech.chains)
    for placement in mech.chains:
        trsf = children[placement.name].loc.wrapped.Transformation()
        for local, expected in (((0.0, 0.0, 0.0), placement.point_a),
                                ((placement.chain.length, 0.0, 0.0), placement.point_b)):
            p = cq.Vector(*local).transform(cq.Matrix(trsf))
            # rotation and translation of 0.15 m chains in float64: round-off ~1e-17 m
            np.testing.assert_allclose(p.toTuple(), expected, atol=1e-12)
    path = export_step(assembly, tmp_path / "mechanism.step")
    total = sum(chain_volume(c.chain) for c in mech.chains)
    assert import_step(path).Volume() == pytest.approx(total, rel=VOLUME_RTOL)


def test_parameters_are_checked_before_cadquery_runs(monkeypatch):
    def no_cad(*args, **kwargs):
        raise AssertionError("CadQuery was called")

    monkeypatch.setattr(cq.Solid, "makeBox", no_cad)
    monkeypatch.setattr(cq.Workplane, "extrude", no_cad)
    with pytest.raises(ValueError, match="thickness"):
        hinge_solid(CircularNotchHinge(radius=5e-3, thickness=0.0, width=10e-3, block_length=5e-3))
    with pytest.raises(ValueError, match="below the 1 um"):
        hinge_solid(CircularNotchHinge(radius=5e-3, thickness=1e-8, width=10e-3, block_length=5e-3))
    with pytest.raises(ValueError, match="block step"):
        hinge_solid(LeafHinge(length=20e-3, thickness=4e-3, width=40e-3, fillet=6e-3, block_length=10e-3,
                              block_height=16e-3 + 1e-8))
    with pytest.raises(TypeError, match="FlexureChain"):
        hinge_solid(DRIVING)
    with pytest.raises(TypeError, match="FlexureChain"):
        chain_solid(NOTCH)
