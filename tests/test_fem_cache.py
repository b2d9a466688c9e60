"""Content-addressed NPZ cache."""

from __future__ import annotations

import dataclasses
import logging
import os

import numpy as np
import pytest

from flexcal.fem import cache
from flexcal.geometry.params import STEEL, CircularNotchHinge

HINGE = CircularNotchHinge(radius=5e-3, thickness=1e-3, width=10e-3, block_length=5e-3)
PARTS = {"kind": "hinge_compliance", "hinge": HINGE, "mesh": {"n_thickness": 3, "curved": True}, "material": STEEL}


def test_key_is_stable_and_sensitive():
    key = cache.cache_key(PARTS)
    assert key == cache.cache_key(dict(reversed(list(PARTS.items()))))  # order-free
    assert len(key) == 64
    thinner = dict(PARTS, hinge=dataclasses.replace(HINGE, thickness=0.9e-3))
    finer = dict(PARTS, mesh={"n_thickness": 4, "curved": True})
    softer = dict(PARTS, material=dataclasses.replace(STEEL, youngs_modulus=200e9))
    keys = {cache.cache_key(p) for p in (PARTS, thinner, finer, softer)}
    assert len(keys) == 4
    # a float perturbed in the last bit is a different design
    nudged = dict(PARTS, hinge=dataclasses.replace(HINGE, radius=np.nextafter(5e-3, 1.0)))
    assert cache.cache_key(nudged) != key


def test_code_version_enters_the_key(monkeypatch):
    key = cache.cache_key(PARTS)
    monkeypatch.setattr(cache, "code_version", lambda: "other")
    assert cache.cache_key(PARTS) != key


@pytest.mark.parametrize("edited, changes", [("geometry/solids.py", True), ("fem/mesh.py", True),
                                              ("geometry/profiles/leaf.py", True), ("geometry/schema.py", False),
                                              ("geometry/export.py", False), ("geometry/mount.py", False)])
def test_code_version_follows_the_sources_of_solids_and_meshes(monkeypatch, edited, changes):
    """An edit of a module that makes solids or meshes is a new code version (every key new);
    an edit of the input layer or the STEP writer is not (it used to be: a cold rebuild)."""
    from pathlib import Path

    before = cache._sources_version()
    read_bytes = Path.read_bytes

    def edited_read(path):
        data = read_bytes(path)
        return data + b"# edited\n" if path.as_posix().endswith(edited) else data

    monkeypatch.setattr(Path, "read_bytes", edited_read)
    assert (cache._sources_version() != before) == changes


def test_code_version_is_read_once_per_process(monkeypatch):
    """The sources are read and hashed at the first key only: later keys reread nothing, and
    a source edited (or committed) while the process runs does not change its keys halfway."""
    from pathlib import Path

    first = cache.cache_key(PARTS)
    version = cache.code_version()
    read_bytes = Path.read_bytes
    reads = []

    def edited_read(path):
        reads.append(path)
        return read_bytes(path) + b"# edited\n"

    monkeypatch.setattr(Path, "read_bytes", edited_read)
    assert cache._sources_version() != version  # the edit is there on disk, as it were
    reads.clear()
    assert [cache.cache_key(PARTS) for _ in range(3)] == [first] * 3
    assert cache.code_version() == version
    assert reads == []  # no source reread per lookup


def test_unkeyable_values_are_rejected():
    with pytest.raises(ValueError, match="cannot key"):
        cache.cache_key({"x": object()})
    with pytest.raises(ValueError, match="non-finite"):
        cache.cache_key({"x": float("nan")})


def test_cached_computes_once_and_round_trips(tmp_path):
    calls = []

    def compute():
        calls.append(1)
        return {"compliance": np.arange(36.0).reshape(6, 6), "n": np.array(7)}

    first = cache.cached(PARTS, compute, tmp_path)
    second = cache.cached(PARTS, compute, tmp_path)
    assert len(calls) == 1
    np.testing.assert_array_equal(first["compliance"], second["compliance"])
    assert int(second["n"]) == 7
    assert [p.name for p in tmp_path.iterdir()] == [f"{cache.cache_key(PARTS)}.npz"]  # no temporaries left


def test_environment_variable_sets_the_folder(tmp_path, monkeypatch):
    monkeypatch.setenv(cache.CACHE_ENV, str(tmp_path / "c"))
    assert cache.cache_dir() == tmp_path / "c"
    cache.cached(PARTS, lambda: {"a": np.ones(2)})
    assert len(list((tmp_path / "c").glob("*.npz"))) == 1
    monkeypatch.delenv(cache.CACHE_ENV)
    assert cache.cache_dir().parts[-2:] == (".cache", "flexcal")


def test_damaged_file_is_recomputed(tmp_path):
    key = cache.cache_key(PARTS)
    (tmp_path / f"{key}.npz").write_bytes(b"not a zip file")
    assert cache.load_cached(key, tmp_path) is None
    result = cache.cached(PARTS, lambda: {"a": np.ones(3)}, tmp_path)
    np.testing.assert_array_equal(cache.load_cached(key, tmp_path)["a"], result["a"])


def test_failed_write_leaves_nothing(tmp_path):
    class Unwritable:
        def __array__(self, dtype=None, copy=None):
            raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        cache.store_cached(cache.cache_key(PARTS), {"a": Unwritable()}, tmp_path)
    assert list(tmp_path.iterdir()) == []


def _counting(value):
    calls = []

    def compute():
        calls.append(1)
        return {"compliance": np.full((6, 6), value)}

    return compute, calls


def test_truncated_file_is_recomputed(tmp_path):
    cache.cached(PARTS, lambda: {"compliance": np.arange(36.0).reshape(6, 6)}, tmp_path)
    path = tmp_path / f"{cache.cache_key(PARTS)}.npz"
    for keep in (len(path.read_bytes()) // 2, 100, 0):  # cut inside the data, inside the header, empty
        data = path.read_bytes()
        path.write_bytes(data[:keep])
        compute, calls = _counting(float(keep))
        result = cache.cached(PARTS, compute, tmp_path)
        assert calls == [1]
        assert result["compliance"][0, 0] == float(keep)
        assert cache.load_cached(cache.cache_key(PARTS), tmp_path)["compliance"][0, 0] == float(keep)  # rewritten


def test_entry_of_another_key_is_recomputed(tmp_path):
    other = dict(PARTS, mesh={"n_thickness": 5, "curved": True})
    cache.cached(other, lambda: {"compliance": np.ones((6, 6))}, tmp_path)
    key, other_key = cache.cache_key(PARTS), cache.cache_key(other)
    # a file copied (or renamed) onto the wrong name holds results of other inputs
    (tmp_path / f"{key}.npz").write_bytes((tmp_path / f"{other_key}.npz").read_bytes())
    assert cache.load_cached(key, tmp_path) is None
    compute, calls = _counting(2.0)
    assert cache.cached(PARTS, compute, tmp_path)["compliance"][0, 0] == 2.0
    assert calls == [1]
    assert cache.load_cached(other_key, tmp_path)["compliance"][0, 0] == 1.0  # the right file is untouched


def test_flipped_bits_in_the_data_are_detected(tmp_path):
    values = np.linspace(1.0, 2.0, 36).reshape(6, 6)
    cache.cached(PARTS, lambda: {"compliance": values}, tmp_path)
    path = tmp_path / f"{cache.cache_key(PARTS)}.npz"
    data = bytearray(path.read_bytes())
    offset = bytes(data).index(values.tobytes()) + 17  # inside the stored float64s (uncompressed NPZ)
    data[offset] ^= 0x40
    path.write_bytes(bytes(data))
    assert cache.load_cached(cache.cache_key(PARTS), tmp_path) is None
    compute, calls = _counting(3.0)
    assert cache.cached(PARTS, compute, tmp_path)["compliance"][0, 0] == 3.0 and calls == [1]


@pytest.mark.parametrize("extra", [{}, {"__key__": "KEY"}, {"__digest__": "0" * 64}],
                         ids=["no-key-no-digest", "key-only", "digest-only"])
def test_entries_of_the_older_format_are_recomputed(tmp_path, extra):
    # files written before keys and digests were stored (or with one of them stripped):
    # nothing vouches for their numbers, here doubled by hand, so they are a miss
    key = cache.cache_key(PARTS)
    stored = {name: np.array(key if value == "KEY" else value) for name, value in extra.items()}
    np.savez(tmp_path / f"{key}.npz", compliance=2.0 * np.eye(6), **stored)
    assert cache.load_cached(key, tmp_path) is None
    compute, calls = _counting(1.0)
    assert cache.cached(PARTS, compute, tmp_path)["compliance"][0, 0] == 1.0 and calls == [1]
    assert cache.load_cached(key, tmp_path)["compliance"][0, 0] == 1.0  # replaced by a keyed, digested file


def test_stored_files_hold_key_and_digest_but_loads_do_not(tmp_path):
    path = cache.store_cached(cache.cache_key(PARTS), {"a": np.ones(3)}, tmp_path)
    with np.load(path) as data:
        assert str(data["__key__"]) == cache.cache_key(PARTS)
        assert set(data.files) == {"a", "__key__", "__digest__"}
    assert set(cache.load_cached(cache.cache_key(PARTS), tmp_path)) == {"a"}
    with pytest.raises(ValueError, match="reserved"):
        cache.store_cached(cache.cache_key(PARTS), {"__key__": np.ones(1)}, tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


# --- a cache folder that cannot be written (issue 23) -------------------------------------
# Tests run as root, so mode bits cannot make a folder unwritable: the folder is put below
# a regular file (ENOTDIR, as a mistyped FLEXCAL_CACHE_DIR would) or the write is made to
# fail the way a read-only mount or a full disk fails it.

def _below_a_file(tmp_path):
    (tmp_path / "a-file").write_text("not a folder")
    return tmp_path / "a-file" / "cache"


def _cache_warnings(caplog):
    return [r for r in caplog.records if r.name == "flexcal.fem.cache" and r.levelno == logging.WARNING]


def test_unwritable_folder_warns_once_before_computing_and_keeps_the_results(tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="flexcal.fem.cache")
    folder = _below_a_file(tmp_path)
    warned_before_compute = []

    def compute():
        warned_before_compute.append(len(_cache_warnings(caplog)))
        return {"compliance": np.arange(36.0).reshape(6, 6)}

    first = cache.cached(PARTS, compute, folder)
    np.testing.assert_array_equal(first["compliance"], np.arange(36.0).reshape(6, 6))
    assert warned_before_compute == [1]                        # the warning came before the work
    other = dict(PARTS, mesh={"n_thickness": 4, "curved": True})
    cache.cached(other, lambda: {"compliance": np.ones((6, 6))}, folder)
    again = cache.cached(PARTS, compute, folder)               # served from this process's memory
    assert warned_before_compute == [1] and len(_cache_warnings(caplog)) == 1  # once per folder
    np.testing.assert_array_equal(again["compliance"], first["compliance"])
    again["compliance"][0, 0] = -1.0                            # a copy: the kept result stays intact
    assert cache.load_cached(cache.cache_key(PARTS), folder)["compliance"][0, 0] == 0.0
    message = _cache_warnings(caplog)[0].getMessage()
    assert str(folder) in message and "Not a directory" in message and cache.CACHE_ENV in message
    assert not cache.cache_is_writable(folder)


def test_write_failing_after_the_compute_keeps_the_result(tmp_path, caplog, monkeypatch):
    """The folder passes the check, then the final rename fails (a mount turned read-only)."""
    caplog.set_level(logging.WARNING, logger="flexcal.fem.cache")
    assert cache.cache_is_writable(tmp_path)

    def refuse(source, target):
        raise PermissionError(13, "Permission denied", str(target))

    monkeypatch.setattr(cache.os, "replace", refuse)
    compute, calls = _counting(4.0)
    assert cache.cached(PARTS, compute, tmp_path)["compliance"][0, 0] == 4.0
    assert cache.cached(PARTS, compute, tmp_path)["compliance"][0, 0] == 4.0 and calls == [1]
    assert len(_cache_warnings(caplog)) == 1 and "Permission denied" in _cache_warnings(caplog)[0].getMessage()
    assert list(tmp_path.iterdir()) == []                       # no temporary left behind


def test_read_only_folder_still_serves_its_entries(tmp_path, caplog, monkeypatch):
    caplog.set_level(logging.WARNING, logger="flexcal.fem.cache")
    cache.cached(PARTS, lambda: {"compliance": np.full((6, 6), 5.0)}, tmp_path)
    readonly = tmp_path.parent / f"{tmp_path.name}-ro"
    tmp_path.rename(readonly)

    def read_only(*args, **kwargs):
        raise OSError(30, "Read-only file system", str(readonly))

    monkeypatch.setattr(cache.tempfile, "mkstemp", read_only)
    compute, calls = _counting(6.0)
    assert cache.cached(PARTS, compute, readonly)["compliance"][0, 0] == 5.0 and calls == []
    assert len(_cache_warnings(caplog)) == 1


@pytest.mark.parametrize("how", ["folder-below-a-file", "rename-fails"])
def test_fem_hinge_completes_without_a_writable_cache(tmp_path, monkeypatch, caplog, how):
    """A real (coarse, mapped-mesh) FEM hinge: same numbers as with a working cache, one
    warning, and that warning before the FEM work when the folder is unusable up front."""
    from flexcal.validation.reports.fem import compare_hinge

    caplog.set_level(logging.WARNING, logger="flexcal.fem.cache")  # an earlier `cli.main(... -q)` may have raised it

    def solve(folder):
        monkeypatch.setenv(cache.CACHE_ENV, str(folder))
        events = []
        handler = logging.Handler()
        handler.emit = lambda record: events.append(f"warning: {record.getMessage()}")
        logger = logging.getLogger("flexcal.fem.cache")
        logger.addHandler(handler)
        try:
            result = compare_hinge(HINGE, elements_through_thickness=1, mesher="mapped", cache=True,
                                   stage=events.append)
        finally:
            logger.removeHandler(handler)
        return result, events

    reference, events = solve(tmp_path / "working")
    assert not [e for e in events if e.startswith("warning")] and list((tmp_path / "working").glob("*.npz"))
    if how == "folder-below-a-file":
        result, events = solve(_below_a_file(tmp_path))
    else:
        real_replace = os.replace

        def refuse(source, target):
            if str(target).startswith(str(tmp_path / "failing")):
                raise PermissionError(13, "Permission denied", str(target))
            return real_replace(source, target)

        monkeypatch.setattr(os, "replace", refuse)
        result, events = solve(tmp_path / "failing")
    warnings = [i for i, e in enumerate(events) if e.startswith("warning")]
    assert len(warnings) == 1
    if how == "folder-below-a-file":
        assert warnings[0] < events.index("CadQuery solid")      # warned before any FEM work
    # the mapped mesher is deterministic: the same mesh and the same numbers to the bit
    np.testing.assert_array_equal(result.compliance_fem, reference.compliance_fem)
    np.testing.assert_array_equal(result.displacement, reference.displacement)
    assert result.timings.keys() == {"geometry", "mesh", "fem_solve"}  # computed here, not served


def test_yield_strength_stays_out_of_the_key():
    # no cached FEM result (stiffness, mass, stress per unit motion) depends on the yield
    # strength: changing it must keep the entries; the elastic constants must not
    stronger = dict(PARTS, material=dataclasses.replace(STEEL, yield_strength=900e6))
    assert cache.cache_key(stronger) == cache.cache_key(PARTS)
    denser = dict(PARTS, material=dataclasses.replace(STEEL, density=8000.0))
    stiffer_nu = dict(PARTS, material=dataclasses.replace(STEEL, poisson_ratio=0.3))
    assert len({cache.cache_key(p) for p in (PARTS, denser, stiffer_nu)}) == 3


def test_two_threads_asking_for_one_entry_compute_it_once(tmp_path, monkeypatch):
    """``cached`` on job threads (the tied chains' shared segments, session 26): a thread asking
    for an entry another thread is computing waits and reads that one's result; a different
    entry is computed meanwhile, not after."""
    import threading
    import time

    started, release, calls, missed = threading.Event(), threading.Event(), [], threading.Event()
    load = cache.load_cached

    def watched(key, directory=None):
        found = load(key, directory)
        if threading.current_thread().name == "second" and found is None:
            missed.set()  # the second thread found no entry: it computes or waits from here
        return found

    monkeypatch.setattr(cache, "load_cached", watched)

    def slow():
        calls.append("slow")
        started.set()
        assert release.wait(10.0)  # 10 s: the test's threads hold nothing else
        return {"value": np.arange(3.0)}

    first = threading.Thread(target=cache.cached, args=(PARTS, slow, tmp_path))
    first.start()
    assert started.wait(10.0)
    results = []
    second = threading.Thread(target=lambda: results.append(cache.cached(PARTS, slow, tmp_path)), name="second")
    second.start()
    assert missed.wait(10.0)
    time.sleep(0.2)  # time enough for a second computation to start, were there one
    other = cache.cached(dict(PARTS, kind="other"), lambda: {"value": np.ones(2)}, tmp_path)  # not blocked
    np.testing.assert_array_equal(other["value"], np.ones(2))
    release.set()
    first.join(10.0)
    second.join(10.0)
    assert calls == ["slow"] and len(results) == 1
    np.testing.assert_array_equal(results[0]["value"], np.arange(3.0))
    assert not cache._COMPUTING  # the locks go with the entries written


def test_a_failed_computation_lets_the_next_thread_compute(tmp_path):
    def fails():
        raise RuntimeError("no")

    with pytest.raises(RuntimeError):
        cache.cached(PARTS, fails, tmp_path)
    assert not cache._COMPUTING
    np.testing.assert_array_equal(cache.cached(PARTS, lambda: {"value": np.ones(1)}, tmp_path)["value"], np.ones(1))


def _blas_threads() -> set[int]:
    """The thread counts of the loaded OpenBLAS pools (numpy's and scipy's BLAS; MKL serves PARDISO
    only, on ``solve._PER_THREAD.mkl_threads``)."""
    from threadpoolctl import threadpool_info

    return {pool["num_threads"] for pool in threadpool_info() if pool["internal_api"] == "openblas"}


def test_an_entry_is_computed_on_one_thread_and_the_pools_given_back(tmp_path):
    """``compute`` runs with PARDISO on one MKL thread (this thread's count) and, on the main
    thread, OpenBLAS's pools on one thread (fem.solve.one_thread: the same bits on any machine or
    batch); after, the pools are as they were. On a job thread the PARDISO count is that
    thread's own (its executor holds the pools)."""
    import threading

    from threadpoolctl import threadpool_limits

    from flexcal.fem import solve

    seen = []

    def compute():
        seen.append((threading.current_thread() is threading.main_thread(),
                     getattr(solve._PER_THREAD, "mkl_threads", 0), _blas_threads()))
        return {"x": np.zeros(1)}

    with threadpool_limits(2, user_api="blas"):
        assert _blas_threads() == {2}
        cache.cached({**PARTS, "entry": 1}, compute, tmp_path)
        assert _blas_threads() == {2}  # given back
        job = threading.Thread(target=cache.cached, args=({**PARTS, "entry": 2}, compute, tmp_path))
        job.start()
        job.join(10)
    assert seen[0] == (True, 1, {1})
    assert seen[1][:2] == (False, 1)
