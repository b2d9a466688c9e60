"""numba keys a cached kernel by its own source file only: a change to a function it compiles
in from another file (an inlined helper, ``serial``'s Eq. 1 terms) or to a constant it reads
from one (``point_status``) leaves the cached kernel as it was (numba's documented limit,
"Notes on Caching"). Each kernel module therefore names those files with a digest of their
text (``SOURCES_COMPILED_IN``): a change to one of them fails the first test below until the
digest is written into the kernel module, whose own text then changes, so numba compiles it
again on every machine that cached the old one."""

import ast
import hashlib
import importlib
from pathlib import Path

import pytest

import flexcal.model

ROOT = Path(flexcal.model.__file__).parents[1]  # the package's folder (an editable install has no plain __path__)


def kernel_modules() -> list:
    """Every module of the package that caches a numba kernel (``njit`` with ``cache=True``)."""
    packages = [d for d in ROOT.iterdir() if (d / "__init__.py").is_file() and d.name not in ("tests", "benchmarks")]
    files = [f for d in packages for f in d.rglob("*.py") if "njit" in (text := f.read_text()) and "cache=True" in text]
    return [importlib.import_module(".".join(("flexcal",) + f.relative_to(ROOT).with_suffix("").parts)) for f in files]


KERNEL_MODULES = kernel_modules()


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def stale(module, folder: Path | None = None) -> list[str]:
    """The files ``module`` names whose text in ``folder`` (its own by default) no longer has the
    recorded digest."""
    folder = folder or Path(module.__file__).parent
    return [name for name, recorded in module.SOURCES_COMPILED_IN.items() if recorded != digest(folder / name)]


def model_imports(module) -> set[str]:
    """The files of model/ that ``module`` imports (relative imports: ``from .x import`` and
    ``from . import x``)."""
    tree = ast.parse(Path(module.__file__).read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            names |= {f"{node.module}.py"} if node.module else {f"{a.name}.py" for a in node.names}
    return names


@pytest.mark.parametrize("module", KERNEL_MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_each_kernel_module_holds_the_digests_of_the_files_it_compiles_in(module):
    fixes = {name: digest(Path(module.__file__).parent / name) for name in stale(module)}
    assert not fixes, (f"{sorted(fixes)} changed: numba's cache of {module.__name__} would keep the old code; "
                       f"write {fixes} into SOURCES_COMPILED_IN of {Path(module.__file__).name}")


@pytest.mark.parametrize("module", KERNEL_MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_every_model_file_a_kernel_module_imports_is_named_with_a_digest(module):
    assert model_imports(module) == set(module.SOURCES_COMPILED_IN)


def test_the_kernel_modules_are_found():
    names = {m.__name__.rsplit(".", 1)[-1] for m in KERNEL_MODULES}
    assert {"_numba_kernels", "_numba_consistent", "_numba_shortening", "_recurrences"} <= names


def test_an_edited_dependency_is_found_stale(tmp_path):
    from flexcal.model import _numba_consistent

    model = Path(_numba_consistent.__file__).parent
    for name in _numba_consistent.SOURCES_COMPILED_IN:
        (tmp_path / name).write_bytes((model / name).read_bytes())
    assert stale(_numba_consistent, tmp_path) == []
    with open(tmp_path / "point_status.py", "a") as f:
        f.write("# an edit\n")
    assert stale(_numba_consistent, tmp_path) == ["point_status.py"]
