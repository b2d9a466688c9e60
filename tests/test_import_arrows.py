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
    depth = len(path.relative_to(package_dir).parts)  # package levels below flexcal: 1 for package/x.py, 2 for package/sub/x.py and package/sub/__init__.py
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


def module_name(path: Path) -> str:
    """'validation.prototype.mechanism' for validation/prototype/mechanism.py (package folders
    as the repository holds them; an __init__.py is its package)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def module_arrows(path: Path) -> set[str]:
    """The flexcal modules one file imports (lazy imports too), as ``module_name`` gives them:
    ``from .x import a`` is an arrow to ``x`` when x is a module, ``from . import x`` to ``x``."""
    here = module_name(path).split(".")
    package = here if path.name == "__init__.py" else here[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        bases = []
        if isinstance(node, ast.Import):
            bases = [alias.name.split(".")[1:] for alias in node.names if alias.name.startswith("flexcal.")]
            names = [[]]
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                if not (node.module or "").startswith("flexcal."):
                    continue
                bases = [node.module.split(".")[1:]]
            else:
                anchor = package[:len(package) - node.level + 1]
                bases = [anchor + (node.module.split(".") if node.module else [])]
            names = [[alias.name] for alias in node.names]
        for base in bases:
            for name in names:
                for candidate in (base + name, base):  # a submodule, else the module it is taken from
                    dotted = ".".join(candidate)
                    if (ROOT.joinpath(*candidate).with_suffix(".py").exists()
                            or (ROOT.joinpath(*candidate) / "__init__.py").exists()):
                        found.add(dotted)
                        break
    return found - {module_name(path)}


def import_graph() -> dict[str, set[str]]:
    return {module_name(path): module_arrows(path)
            for package in ALLOWED for path in sorted((ROOT / package).rglob("*.py"))}


def test_the_module_reader_resolves_relative_imports():
    arrows = module_arrows(ROOT / "validation" / "cli" / "truth.py")
    assert "validation.cli.options" in arrows  # from .options import add_out, ...
    assert "validation.prototype.providers" in arrows  # from ..prototype.providers import ... (lazy)


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph.get(node, ()):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_the_cycle_finder_finds_a_circle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_circle_between_modules():
    assert cycles(import_graph()) == []


def test_no_numerics_module_imports_the_command_line():
    # the command line (validation/cli/) sits on top: it imports the numerics, never the reverse
    wrong = [f"{module} imports {target}" for module, targets in import_graph().items()
             if not module.startswith("validation.cli")
             for target in targets if target.startswith("validation.cli")]
    assert not wrong, "\n".join(wrong)
