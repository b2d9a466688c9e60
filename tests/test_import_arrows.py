"""The one-way import arrows between flexcal's packages (docs/architecture.md), read from
the source with ``ast``: every ``import`` / ``from ... import`` of a flexcal package,
at module level or inside a function (a lazy import is still an arrow)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# each package and the packages it may import (geometry <- fem; geometry <- model <- calibration <- validation)
ALLOWED = {
    "geometry": set(),
    "fem": {"geometry"},
    "model": {"geometry"},
    "calibration": {"geometry", "model"},
    "validation": {"geometry", "fem", "model", "calibration"},
}


def imported_packages(path: Path, package_dir: Path) -> dict[str, int]:
    """{flexcal package imported by the file: first line number}; relative imports that
    climb out of the package folder ``package_dir`` count as the package they reach."""
    depth = len(path.relative_to(package_dir).parts) - (path.name == "__init__.py")  # 1 for package/x.py
    found: dict[str, int] = {}
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                names = [node.module or ""]
            elif node.level == depth + 1:  # climbs to flexcal itself: flexcal.<module> or flexcal.<name>
                names = [f"flexcal.{node.module}"] if node.module else [f"flexcal.{a.name}" for a in node.names]
        for name in names:
            parts = name.split(".")
            if len(parts) > 1 and parts[0] == "flexcal":
                found.setdefault(parts[1], node.lineno)
    return found


def test_the_reader_sees_absolute_lazy_and_relative_imports(tmp_path):
    # the check below is only as good as this reader: it must find each kind of import
    package = tmp_path / "model"
    (package / "sub").mkdir(parents=True)
    source = package / "sub" / "x.py"
    source.write_text("import flexcal.fem.mesh\n"
                      "def f():\n    from flexcal.calibration import pso\n"
                      "from ... import validation\n"
                      "from ...geometry.params import Material\n"
                      "from ..frames import skew\n"
                      "import numpy\n")
    assert imported_packages(source, package) == {"fem": 1, "calibration": 3, "validation": 4, "geometry": 5}


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_no_import_runs_up_the_picture(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"no sources under {ROOT / package}"
    wrong = [f"{path.relative_to(ROOT)}:{line} imports flexcal.{target}"
             for path in files
             for target, line in imported_packages(path, ROOT / package).items()
             if target != package and target not in ALLOWED[package]]
    assert not wrong, "\n".join(wrong)
