"""FEM results for people: nodal stress, VTU files for ParaView, deformed-shape PNGs.

pyvista is imported inside the functions that need it. Files are written whole or not
at all (``flexcal.geometry.atomic.atomic_path``: a temporary name in the target folder, then a rename).

Nodal stress is recovered by evaluating each element's stress at its own ten nodes and
averaging over the elements that share the node (unweighted). For a P2 field the
element values are exact at the nodes for linear stress fields; at stress gradients and
singular corners the average smooths the jump between elements.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from flexcal.geometry.atomic import atomic_path
from flexcal.geometry.params import Material

from .assembly import check_mesh
from .elements import elasticity_matrix, element_strain_at_nodes

__all__ = ["nodal_stress", "von_mises", "to_pyvista", "write_vtu", "render_deformed_png", "render_mesh_png"]

VTK_QUADRATIC_TETRA = 24


def _displacement_array(mesh, u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, float)
    n_nodes = len(mesh.nodes)
    if u.shape == (3 * n_nodes,):
        u = u.reshape(n_nodes, 3)
    if u.shape != (n_nodes, 3):
        raise ValueError(f"displacement has shape {u.shape}; expected ({n_nodes}, 3) or ({3 * n_nodes},) [m]")
    return u


def nodal_stress(mesh, material: Material, u: np.ndarray) -> np.ndarray:
    """Cauchy stress at the nodes (n_nodes, 6) [Pa], Voigt order xx, yy, zz, yz, xz, xy,
    from displacements u (n_nodes, 3) or (3 n_nodes,) [m] (element values at the nodes,
    averaged over the elements sharing each node)."""
    nodes, tets = check_mesh(mesh)
    u = _displacement_array(mesh, u)
    strain = element_strain_at_nodes(nodes[tets], u[tets])  # (e, 10, 6)
    stress = strain @ elasticity_matrix(material).T
    total = np.zeros((len(nodes), 6))
    np.add.at(total, tets.ravel(), stress.reshape(-1, 6))
    count = np.bincount(tets.ravel(), minlength=len(nodes))
    return total / count[:, None]


def von_mises(stress: np.ndarray) -> np.ndarray:
    """Von Mises equivalent stress (...,) [Pa] of Voigt stresses (..., 6) [Pa]."""
    s = np.asarray(stress, float)
    sxx, syy, szz, syz, sxz, sxy = np.moveaxis(s, -1, 0)
    return np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3.0 * (syz**2 + sxz**2 + sxy**2))


def to_pyvista(mesh, displacement: np.ndarray | None = None, material: Material | None = None, point_data=None):
    """A ``pyvista.UnstructuredGrid`` of VTK_QUADRATIC_TETRA cells, coordinates [m].

    With ``displacement`` (n_nodes, 3) [m]: point data ``displacement`` [m] and
    ``displacement_magnitude`` [m]; with ``material`` too: ``stress`` (Voigt, [Pa]) and
    ``von_mises`` [Pa]. ``point_data``: extra {name: (n_nodes, ...) array}."""
    import pyvista as pv

    nodes, tets = check_mesh(mesh)
    cells = np.hstack([np.full((len(tets), 1), 10, dtype=np.int64), tets]).ravel()
    grid = pv.UnstructuredGrid(cells, np.full(len(tets), VTK_QUADRATIC_TETRA, dtype=np.uint8), nodes.copy())
    if displacement is not None:
        u = _displacement_array(mesh, displacement)
        grid.point_data["displacement"] = u
        grid.point_data["displacement_magnitude"] = np.linalg.norm(u, axis=1)
        if material is not None:
            stress = nodal_stress(mesh, material, u)
            grid.point_data["stress"] = stress
            grid.point_data["von_mises"] = von_mises(stress)
    for name, values in (point_data or {}).items():
        values = np.asarray(values)
        if values.shape[0] != len(nodes):
            raise ValueError(f"point data {name!r} has {values.shape[0]} rows; the mesh has {len(nodes)} nodes")
        grid.point_data[name] = values
    return grid


def write_vtu(
    mesh,
    path: str | os.PathLike,
    displacement: np.ndarray | None = None,
    material: Material | None = None,
    point_data=None,
) -> Path:
    """Write the mesh (and displacement, stress, von Mises; see ``to_pyvista``) as a VTU
    file for ParaView. Returns the path."""
    path = Path(path)
    if path.suffix != ".vtu":
        raise ValueError(f"{path} must end in .vtu")
    grid = to_pyvista(mesh, displacement, material, point_data)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        grid.save(tmp, binary=True)
    return path


def _choose_headless_window() -> None:
    """Without a display, ask VTK for its EGL window right away: it tries X first by
    default and prints "bad X server connection" (a warning on every run) before falling
    back to EGL. Same pictures, byte for byte (checked with VTK 9.6 here). A choice the
    user made (``VTK_DEFAULT_OPENGL_WINDOW``) is kept."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def render_deformed_png(
    mesh,
    u: np.ndarray,
    path: str | os.PathLike,
    scale: float | None = None,
    *,
    material: Material | None = None,
    window_size: tuple[int, int] = (1200, 800),
) -> Path:
    """Render the deformed shape off-screen to a PNG.

    u (n_nodes, 3) [m]; ``scale``: displacement magnification (default: the largest
    displacement drawn as 10 % of the bounding-box diagonal). Colour: von Mises stress
    [MPa] with ``material``, else displacement magnitude [um]. The undeformed mesh is
    drawn as a light outline."""
    import pyvista as pv

    _choose_headless_window()
    pv.OFF_SCREEN = True
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"{path} must end in .png")
    u = _displacement_array(mesh, u)
    nodes = np.asarray(mesh.nodes, float)
    largest = float(np.linalg.norm(u, axis=1).max())
    if scale is None:
        diagonal = float(np.linalg.norm(nodes.max(axis=0) - nodes.min(axis=0)))
        scale = 0.1 * diagonal / largest if largest > 0 else 1.0
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale={scale} must be a positive number")
    grid = to_pyvista(mesh, u, material)
    if material is not None:
        grid.point_data["von Mises [MPa]"] = grid.point_data["von_mises"] / 1e6
        scalars = "von Mises [MPa]"
    else:
        grid.point_data["|u| [um]"] = grid.point_data["displacement_magnitude"] * 1e6
        scalars = "|u| [um]"
    deformed = grid.copy()
    deformed.points = nodes + scale * u
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    plotter.add_mesh(grid.extract_feature_edges(), color="grey", opacity=0.4)
    plotter.add_mesh(deformed, scalars=scalars, show_edges=False, cmap="viridis")
    plotter.add_text(f"deformation x {scale:.3g}", font_size=10)
    plotter.view_isometric()
    return _save_screenshot(plotter, path)


def render_mesh_png(mesh, path: str | os.PathLike, *, window_size: tuple[int, int] = (1200, 800)) -> Path:
    """Render the undeformed tet mesh off-screen to a PNG: its surface with the element
    edges drawn, so the density through the necks can be checked by eye."""
    import pyvista as pv

    _choose_headless_window()
    pv.OFF_SCREEN = True
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"{path} must end in .png")
    surface = to_pyvista(mesh).extract_surface(algorithm="dataset_surface")
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    plotter.add_mesh(surface, color="lightsteelblue", show_edges=True, edge_color="black", line_width=0.5)
    plotter.add_text(f"mesh: {len(mesh.nodes)} nodes, {len(mesh.tets)} quadratic tets", font_size=10)
    plotter.view_isometric()
    return _save_screenshot(plotter, path)


def _save_screenshot(plotter, path: Path) -> Path:
    """Screenshot to a temporary name, then rename (whole or nothing); closes the plotter."""
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(path) as tmp:
            plotter.screenshot(str(tmp))
    finally:
        plotter.close()
    return path
