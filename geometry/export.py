"""STEP / STL files of parts and assemblies.

Shapes are in metres inside flexcal; files are written in millimetres (the unit CAD
tools expect): STEP declares MM in its header, STL (which has no unit) is scaled to mm.
``import_step`` reads a STEP file back into metres whatever unit it declares.
Files are written to a temporary name beside the target and renamed (``atomic.atomic_path``),
so a failed export never leaves a partial file; they get the permissions of any new file.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Union

import cadquery as cq
from OCP.BRepTools import BRepTools

from .atomic import atomic_path
from .solids import Part

__all__ = ["export_step", "export_stl", "import_step"]


def _atomic(path: str | os.PathLike, write) -> Path:
    """Call ``write(tmp_name)`` then rename the temporary file to ``path``."""
    target = Path(path)
    if not target.parent.is_dir():
        raise FileNotFoundError(f"folder {target.parent} does not exist; create it first")
    with atomic_path(target) as tmp:
        write(str(tmp))
        if not tmp.is_file() or tmp.stat().st_size == 0:
            raise RuntimeError(f"CadQuery wrote an empty file for {target}")
    return target


def export_step(part_or_assembly: Union[Part, cq.Assembly, cq.Shape], path: str | os.PathLike) -> Path:
    """Write a Part, a bare CadQuery shape or an Assembly (names, colours and placements
    kept) to a STEP file in mm. Returns the path."""
    if isinstance(part_or_assembly, cq.Assembly):
        assembly = part_or_assembly

        def write(tmp: str) -> None:
            assembly.export(tmp, exportType="STEP", unit="M", outputUnit="MM")
    else:
        shape = part_or_assembly.shape if isinstance(part_or_assembly, Part) else part_or_assembly

        def write(tmp: str) -> None:
            status = shape.exportStep(tmp, unit="M", outputUnit="MM")
            if int(status) != 1:  # IFSelect_RetDone
                raise RuntimeError(f"STEP export failed with status {status}")
    return _atomic(path, write)


def export_stl(part: Union[Part, cq.Shape], path: str | os.PathLike, tolerance: float = 1e-5,
               angular_tolerance: float = 0.2) -> Path:
    """Write a binary STL in mm. tolerance [m]: largest distance between the true surface
    and its triangles (absolute, not relative to the part size); angular_tolerance [rad].
    The part's own shape is not modified (a copy is triangulated)."""
    if not (tolerance > 0):
        raise ValueError(f"STL tolerance={tolerance!r} m must be > 0")
    shape = part.shape if isinstance(part, Part) else part
    scaled = shape.copy().scale(1e3)

    def write(tmp: str) -> None:
        BRepTools.Clean_s(scaled.wrapped)
        if not scaled.exportStl(tmp, tolerance * 1e3, angular_tolerance, ascii=False, relative=False):
            raise RuntimeError("STL export failed")
    return _atomic(path, write)


def import_step(path: str | os.PathLike) -> cq.Shape:
    """Read a STEP file into one CadQuery shape in metres (a compound if it holds several)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"STEP file {path} not found")
    shapes = cq.importers.importStep(str(path), unit="M").vals()
    if not shapes:
        raise ValueError(f"STEP file {path} holds no shape")
    return shapes[0] if len(shapes) == 1 else cq.Compound.makeCompound(shapes)
