"""numba keys a cached kernel by its own source file only: a change to a function it compiles
in from another file (an inlined helper, ``serial``'s Eq. 1 terms) or to a constant it reads
from one (``point_status``) leaves the cached kernel as it was (numba's documented limit,
"Notes on Caching"). Each kernel module therefore names those files with a digest of their
text (``SOURCES_COMPILED_IN``): a change to one of them fails the first test below until the
digest is written into the kernel module, whose own text then changes, so numba compiles it
again on every machine that cached the old one."""

import ast
import hashlib
from pathlib import Path

import pytest

from flexcal.model import _numba_consistent, _numba_kernels, _numba_shortening

MODEL = Path(_numba_kernels.__file__).parent
KERNEL_MODULES = (_numba_kernels, _numba_consistent, _numba_shortening)


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def stale(module, folder: Path = MODEL) -> list[str]:
    """The files ``module`` names whose text in ``folder`` no longer has the recorded digest."""
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
    fixes = {name: digest(MODEL / name) for name in stale(module)}
    assert not fixes, (f"{sorted(fixes)} changed: numba's cache of {module.__name__} would keep the old code; "
                       f"write {fixes} into SOURCES_COMPILED_IN of {Path(module.__file__).name}")


@pytest.mark.parametrize("module", KERNEL_MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_every_model_file_a_kernel_module_imports_is_named_with_a_digest(module):
    assert model_imports(module) == set(module.SOURCES_COMPILED_IN)


def test_an_edited_dependency_is_found_stale(tmp_path):
    for name in _numba_consistent.SOURCES_COMPILED_IN:
        (tmp_path / name).write_bytes((MODEL / name).read_bytes())
    assert stale(_numba_consistent, tmp_path) == []
    with open(tmp_path / "point_status.py", "a") as f:
        f.write("# an edit\n")
    assert stale(_numba_consistent, tmp_path) == ["point_status.py"]
