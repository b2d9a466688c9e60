"""The mount seen whole: a picture (pyvista, off-screen) and a STEP file of its solids.

``write_mount_picture(mechanism, path)``: the six chains' CadQuery solids placed in the mount
frame (load chains grey, drives orange, each named), the payload's box (translucent blue
where ``[payload] box_centre_mm`` places it; else a dashed-grey outline centred on the centre
of gravity, labelled "not placed") and the remote centre O_C, seen from behind the payload, above and to its side;
lengths on the picture in mm. ``write_mount_step(mechanism, path)``: the same chains (and
the placed payload box) as one STEP assembly in mm, parts named L1..D3 and "payload".
Both files are written whole or not at all.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from flexcal.geometry.params import MechanismParams

__all__ = ["write_mount_picture", "write_mount_step", "PICTURE_SIZE"]

PICTURE_SIZE = (1400, 1000)  # [px]
_LOAD, _DRIVE, _PAYLOAD = "#9a9aa6", "#e6801a", "#4c7fd9"
# Tessellation of the solids for the picture: 0.2 mm chordal error is below a pixel at this
# size for mounts of ~1 m; 0.3 rad keeps the fillets round.
_CHORD, _ANGLE = 2e-4, 0.3  # [m], [rad]


def _polydata(shape):
    import pyvista as pv

    vertices, triangles = shape.tessellate(_CHORD, _ANGLE)
    points = np.array([[v.x, v.y, v.z] for v in vertices]) * 1e3  # mm on the picture
    faces = np.hstack([np.full((len(triangles), 1), 3), np.asarray(triangles, dtype=np.int64)]).ravel()
    return pv.PolyData(points, faces)


def write_mount_picture(mechanism: MechanismParams, path: str | os.PathLike, *, title: str = "") -> Path:
    """PNG of the mount at ``path`` (module docstring); returns the path."""
    import pyvista as pv

    from ..mount_solids import PAYLOAD, mount_solids, payload_solid
    from ..output import atomic_path

    solids = mount_solids(mechanism)
    plotter = pv.Plotter(off_screen=True, window_size=PICTURE_SIZE)
    plotter.set_background("white")
    placements = {p.name: p for p in mechanism.chains}
    label_points, labels = [], []
    for name, shape in solids.items():
        mesh = _polydata(shape)
        if name == PAYLOAD:
            plotter.add_mesh(mesh, color=_PAYLOAD, opacity=0.35, show_edges=False)
            label_points.append(np.asarray(mechanism.payload_box_centre) * 1e3)
            labels.append("payload")
            continue
        placement = placements[name]
        plotter.add_mesh(mesh, color=_DRIVE if placement.is_driving else _LOAD, smooth_shading=True)
        label_points.append((np.asarray(placement.point_a) + np.asarray(placement.point_b)) * 0.5e3)
        labels.append(name)
    if PAYLOAD not in solids:
        outline = _polydata(payload_solid(mechanism, centre=mechanism.centre_of_gravity)).extract_feature_edges()
        plotter.add_mesh(outline, color="#777777", line_width=1)
        label_points.append((np.asarray(mechanism.centre_of_gravity) + np.asarray(mechanism.payload_box) * 0.5) * 1e3)
        labels.append("payload (not placed)")
        title = f"{title}\npayload box not placed (no payload.box_centre_mm): outline drawn at the centre of gravity"
    plotter.add_mesh(pv.Sphere(radius=6.0, center=(0.0, 0.0, 0.0)), color="black")
    label_points.append(np.zeros(3))
    labels.append("O_C")
    plotter.add_point_labels(np.array(label_points), labels, font_size=18, point_size=1, shape_opacity=0.6,
                             always_visible=True)
    plotter.add_axes(xlabel="x", ylabel="y", zlabel="z")
    if title.strip():
        plotter.add_text(title.strip(), position="upper_left", font_size=12, color="black")
    plotter.view_vector((1.0, -0.8, 0.6), viewup=(0.0, 0.0, 1.0))  # from behind the payload, to the side, above
    plotter.reset_camera()
    target = Path(path)
    with atomic_path(target) as tmp:
        plotter.screenshot(str(tmp))
    plotter.close()
    return target


def write_mount_step(mechanism: MechanismParams, path: str | os.PathLike) -> Path:
    """STEP assembly (mm) of the placed chains and the placed payload box at ``path``."""
    import cadquery as cq

    from flexcal.geometry.export import export_step
    from flexcal.geometry.solids import mechanism_assembly

    from ..mount_solids import PAYLOAD, payload_solid

    assembly = mechanism_assembly(mechanism)
    if mechanism.payload_box_centre is not None:
        assembly.add(payload_solid(mechanism), name=PAYLOAD, color=cq.Color(0.3, 0.5, 0.85, 0.35))
    return export_step(assembly, path)
