"""One write-to-temp-then-rename (flexcal.geometry.atomic, issue #25): every writer goes
through it and gets the permissions of any new file; a failed folder copy leaves no temporary.
(A failed file write keeps the old file: tests/test_output.py.)"""

from __future__ import annotations

import ast
import os
from pathlib import Path

import numpy as np
import pytest

from flexcal.geometry.atomic import atomic_path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("geometry", "fem", "model", "calibration", "validation")
# renames that are not a write of a file: a lock set aside (out_lock), a staging folder
# that becomes --out in one step, and a move between folders (output._move's same-disk case)
NOT_WRITES = {("validation/out_lock.py", "rename"), ("validation/output.py", "rename"),
              ("validation/output.py", "replace")}


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def _renames(path: Path):
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in ("replace", "rename")
                and isinstance(node.func.value, ast.Name) and node.func.value.id == "os"):
            yield node.func.attr, node.lineno


def test_os_replace_is_called_in_one_place():
    found = [f"{path.relative_to(ROOT)}:{line} os.{name}" for package in PACKAGES
             for path in sorted((ROOT / package).rglob("*.py"))
             for name, line in _renames(path)
             if path.relative_to(ROOT).as_posix() != "geometry/atomic.py"
             and (path.relative_to(ROOT).as_posix(), name) not in NOT_WRITES]
    assert found == []  # write with flexcal.geometry.atomic.atomic_path instead


def test_step_files_follow_the_umask(tmp_path, umask_022):
    cq = pytest.importorskip("cadquery")
    from flexcal.geometry.export import export_step

    path = export_step(cq.Workplane().box(0.01, 0.02, 0.03).val(), tmp_path / "box.step")
    assert oct(path.stat().st_mode & 0o777) == oct(0o644)  # like any new file; mkstemp made it 0600
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_cache_files_follow_the_umask(tmp_path, umask_022):
    from flexcal.fem.cache import load_cached, store_cached

    key = "ab" * 32
    path = store_cached(key, {"x": np.arange(3.0)}, tmp_path)
    assert oct(path.stat().st_mode & 0o777) == oct(0o644)
    np.testing.assert_array_equal(load_cached(key, tmp_path)["x"], np.arange(3.0))
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_a_failed_folder_copy_leaves_no_temporary(tmp_path):
    target = tmp_path / "cases"
    with pytest.raises(RuntimeError):
        with atomic_path(target, suffix=".partial") as tmp:
            (tmp / "sub").mkdir(parents=True)
            (tmp / "sub" / "f").write_text("x")
            raise RuntimeError("copy failed")
    assert list(tmp_path.iterdir()) == []


def test_a_writer_error_without_a_file_name_names_the_target(tmp_path):
    target = tmp_path / "b.json"
    with pytest.raises(OSError, match="b.json") as caught:
        with atomic_path(target):
            raise OSError(28, "No space left on device")  # a stream's ENOSPC names no file
    assert caught.value.filename == str(target)
