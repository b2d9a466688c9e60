"""Content-addressed cache of condensed FEM results (NPZ files).

A result is stored under the SHA-256 of a canonical JSON description of everything it
depends on: the geometry parameters, the mesh settings, the material, the load/coupling
description the caller adds, and the code version (the package version plus a hash of
the sources of ``flexcal.fem`` except output and cache modules and of
``flexcal.geometry``, so a change of the numerics, the mesher or the solids never serves
a stale matrix; an entry that other code computes names that code's modules in its parts,
``sources_digest``, e.g. the prototype's tied chains in ``flexcal.validation``).
A repeated run finds the file and costs one ``np.load``.

Location: ``$FLEXCAL_CACHE_DIR`` if set, else ``~/.cache/flexcal``. Files are written
whole or not at all (``flexcal.geometry.atomic.atomic_path``: a temporary file in the same
folder, then a rename).

A folder that cannot be written (below a file, a read-only mount, no permission) never
costs a result: ``cached`` checks it before it computes anything (``cache_is_writable``:
the folder is created and a file made and removed in it, once per folder and process),
and a folder that fails, then or at a later write, gets one warning line (logger
``flexcal.fem.cache``) and the run goes on: results are kept in this process's memory
(``MEMORY_LIMIT_BYTES``, oldest dropped first) and served from there, and computed again
by the next run. Reading works from a read-only folder. Each file
also stores its own key and a SHA-256 of its arrays (entries ``__key__``, ``__digest__``);
a file that cannot be read whole (truncated, garbage), holds a different key (copied or
renamed by hand, written for other inputs) or whose bytes no longer match the digest
(flipped bits) is a miss: it is recomputed and rewritten. Files in the older format
(written before keys and digests were stored) carry neither and are a miss too: nothing
shows that their numbers were not edited, so they are recomputed and replaced.

Usage::

    parts = {"kind": "hinge_compliance", "hinge": hinge, "mesh": {"n_thickness": 3},
             "material": STEEL}
    arrays = cached(parts, lambda: {"compliance": hinge_compliance(...)})
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib.util
import json
import logging
import math
import os
import struct
import tempfile
import threading
import zipfile
import zlib
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from flexcal.geometry.atomic import atomic_path

__all__ = [
    "CACHE_ENV",
    "cache_dir",
    "code_version",
    "sources_digest",
    "canonical",
    "cache_key",
    "load_cached",
    "store_cached",
    "cached",
    "arrays_digest",
    "cache_is_writable",
    "keep_cached",
    "MEMORY_LIMIT_BYTES",
]

CACHE_ENV = "FLEXCAL_CACHE_DIR"

# Every module of flexcal.fem determines cached results except these (output and the
# cache itself). Editing any other one changes the code version and therefore every key;
# new numerics modules (the mesher's helpers) are included automatically.
_NOT_NUMERICS = frozenset({"__init__.py", "cache.py", "results.py"})
# geometry modules no solid or mesh depends on: the typed input layer and the mount file reader
# (files -> params; the params themselves are in every key) and the STEP writer. Leaving one
# out that does matter would serve stale results, so this lists only modules that cannot.
_GEOMETRY_NOT_SOLIDS = frozenset({"__init__.py", "schema.py", "mount.py", "export.py", "atomic.py"})
# dataclass fields no FEM result depends on, left out of the key so that changing them keeps
# the cached entries: a material's yield strength only judges stresses (flexcal structure),
# stiffness, mass and stress fields per unit motion do not depend on it
_NOT_IN_KEY = {"Material": frozenset({"yield_strength"})}
_KEY_ENTRY = "__key__"  # the key stored inside each file, checked on every load
_DIGEST_ENTRY = "__digest__"  # SHA-256 of the arrays (names, dtypes, shapes, bytes)

# results of folders that cannot be written, kept for this process only: a chain's segment
# stiffness is 1 kB, a hinge's mesh and results a few MB; this holds a run's worth of them
MEMORY_LIMIT_BYTES = 512e6
_LOG = logging.getLogger("flexcal.fem.cache")
_LOCK = threading.Lock()  # the FEM segment builds run on threads of this process
_WRITABLE: dict[str, bool] = {}  # folder -> can a file be written there (checked once per process)
_MEMORY: OrderedDict[tuple[str, str], dict[str, np.ndarray]] = OrderedDict()  # (folder, key) -> arrays
# (folder, key) -> the lock a thread holds while it computes that entry (``cached``): a second
# thread asking for it meanwhile waits and reads the first one's result (the tied chains' shared
# segments, session 26); dropped when the entry is written
_COMPUTING: dict[tuple[str, str], threading.RLock] = {}


def arrays_digest(arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 hex digest of named arrays: names, dtypes, shapes and bytes."""
    digest = hashlib.sha256()
    for name in sorted(arrays):
        value = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}|{value.dtype.str}|{value.shape}|".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def cache_dir(path: str | os.PathLike | None = None) -> Path:
    """The cache folder: ``path`` if given, else ``$FLEXCAL_CACHE_DIR``, else
    ``~/.cache/flexcal`` (created on first write)."""
    if path is not None:
        return Path(path)
    env = os.environ.get(CACHE_ENV)
    return Path(env) if env else Path.home() / ".cache" / "flexcal"


@functools.cache
def code_version() -> str:
    """Package version + SHA-256 (first 16 hex) of the sources that determine results:
    ``flexcal.fem`` (all but ``__init__``, ``cache``, ``results``; its C source too) and
    ``flexcal.geometry``, and whether fTetWild runs seeded (``flexcal.fem._entropy`` built).

    Computed once per process (at its first cache key), then remembered: a source edited or
    committed while a process runs does not change that process's keys halfway, and a lookup
    does not reread and hash every source. (A process started later, such as a new worker,
    computes its own.)"""
    return _sources_version()


def _sources_version() -> str:
    """``code_version`` computed afresh from the files on disk."""
    try:
        from importlib.metadata import version

        package = version("flexcal")
    except Exception:  # not installed (running from a source tree)
        package = "unknown"
    from .tetwild_process import mesher_is_seeded

    digest = hashlib.sha256()
    # unseeded fTetWild meshes (no _entropy build) must not be served as seeded ones
    digest.update(b"seeded mesher" if mesher_is_seeded() else b"unseeded mesher")
    # subfolders too (the hinge profiles: geometry/profiles/, fem/profiles/), named by
    # their path below the package's parent so that equal file names cannot collide
    folder = Path(__file__).parent
    sources = [(folder, p) for p in [*folder.rglob("*.py"), *folder.glob("*.c")] if p.name not in _NOT_NUMERICS]
    spec = importlib.util.find_spec("flexcal.geometry")  # the solids the mesher meshes
    for folder in (spec.submodule_search_locations or []) if spec else []:
        sources += [(Path(folder), p) for p in Path(folder).rglob("*.py") if p.name not in _GEOMETRY_NOT_SOLIDS]
    names = sorted((f"{root.name}/{source.relative_to(root).as_posix()}", source) for root, source in sources)
    for name, source in names:
        digest.update(name.encode())
        digest.update(source.read_bytes())
    return f"{package}+{digest.hexdigest()[:16]}"


@functools.cache
def sources_digest(*modules: str) -> str:
    """SHA-256 (first 16 hex) of the source files of ``modules`` (importable names, e.g.
    ``"flexcal.validation.prototype.cut_fields"``), for the key of an entry that code outside
    ``flexcal.fem`` and ``flexcal.geometry`` computes (``code_version`` covers those two only): an
    edit of one of them is then a new key, not a stale entry. Read once per process, like
    ``code_version``."""
    return _modules_digest(modules)


def _modules_digest(modules: tuple[str, ...]) -> str:
    """``sources_digest`` computed afresh from the files on disk."""
    digest = hashlib.sha256()
    for name in modules:
        spec = importlib.util.find_spec(name)
        if spec is None or not spec.origin or not spec.origin.endswith(".py"):
            raise ValueError(f"no Python source for the module {name!r} to key a cache entry on")
        digest.update(name.encode())
        digest.update(Path(spec.origin).read_bytes())
    return digest.hexdigest()[:16]


def canonical(value: Any) -> Any:
    """A JSON-ready form of ``value`` that is equal for equal inputs: dataclasses become
    ``{"__type__": name, fields...}`` (without the fields in ``_NOT_IN_KEY``, e.g. a
    ``Material``'s yield strength), mappings get sorted keys, numpy arrays and
    scalars become lists/numbers (JSON writes floats round-trip exact)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        skip = _NOT_IN_KEY.get(type(value).__qualname__, frozenset())
        fields = {f.name: canonical(getattr(value, f.name)) for f in dataclasses.fields(value) if f.name not in skip}
        return {"__type__": type(value).__qualname__, **fields}
    if isinstance(value, Mapping):
        return {str(k): canonical(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if isinstance(value, (list, tuple)):
        return [canonical(v) for v in value]
    if isinstance(value, np.ndarray):
        return {"__array__": canonical(value.tolist()), "dtype": str(value.dtype), "shape": list(value.shape)}
    if isinstance(value, np.generic):
        return canonical(value.item())
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"cannot key a cache entry on the non-finite number {value!r}")
        return value  # json writes repr(float): round-trip exact
    if value is None or isinstance(value, (bool, int, str)):
        return value
    raise ValueError(f"cannot key a cache entry on a {type(value).__name__}; pass numbers, strings, arrays or dataclasses")


def cache_key(parts: Mapping[str, Any]) -> str:
    """SHA-256 hex digest of ``parts`` plus the code version."""
    text = json.dumps({"code_version": code_version(), "parts": canonical(parts)}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _path(key: str, directory: Path) -> Path:
    if len(key) != 64 or any(c not in "0123456789abcdef" for c in key):
        raise ValueError(f"cache key {key!r} is not a SHA-256 hex digest")
    return directory / f"{key}.npz"


def _mark_unwritable(folder: Path, error: OSError) -> None:
    """Remember that ``folder`` cannot be written; one warning line the first time."""
    with _LOCK:
        first = _WRITABLE.get(str(folder)) is not False
        _WRITABLE[str(folder)] = False
    if first:
        reason = f"{error.strerror}: {error.filename}" if error.strerror and error.filename else str(error)
        _LOG.warning(f"the FEM cache folder {folder} cannot be written ({reason}); this run goes on without it "
                     f"(results kept in memory, computed again next run): set {CACHE_ENV} to a writable folder")


def cache_is_writable(directory: str | os.PathLike | None = None) -> bool:
    """Whether a file can be written in the cache folder (``cache_dir(directory)``),
    checked by creating the folder and a file in it (mode bits say nothing for root or a
    read-only mount), once per folder and process; False also warns once."""
    folder = cache_dir(directory)
    with _LOCK:
        known = _WRITABLE.get(str(folder))
    if known is not None:
        return known
    try:
        folder.mkdir(parents=True, exist_ok=True)
        handle, probe = tempfile.mkstemp(prefix=".writable.", suffix=".tmp", dir=folder)
        os.close(handle)
        os.unlink(probe)
    except OSError as error:
        _mark_unwritable(folder, error)
        return False
    with _LOCK:
        _WRITABLE.setdefault(str(folder), True)
    return True


def _remember(folder: Path, key: str, arrays: Mapping[str, np.ndarray]) -> None:
    """Keep ``arrays`` in memory under (folder, key), dropping the oldest entries beyond
    ``MEMORY_LIMIT_BYTES``."""
    kept = {name: np.array(value) for name, value in arrays.items()}
    with _LOCK:
        _MEMORY[(str(folder), key)] = kept
        _MEMORY.move_to_end((str(folder), key))
        while sum(a.nbytes for entry in _MEMORY.values() for a in entry.values()) > MEMORY_LIMIT_BYTES:
            _MEMORY.popitem(last=False)


def load_cached(key: str, directory: str | os.PathLike | None = None) -> dict[str, np.ndarray] | None:
    """The arrays stored under ``key``, or ``None``: missing file, unreadable or truncated
    file, a file without a stored key or digest (older format), a file holding another
    key, or arrays whose digest does not match. Arrays kept in memory because the folder
    could not be written (``keep_cached``) are served first, as copies."""
    folder = cache_dir(directory)
    with _LOCK:
        kept = _MEMORY.get((str(folder), key))
    if kept is not None:
        return {name: value.copy() for name, value in kept.items()}
    path = _path(key, folder)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error, struct.error):
        return None
    stored_key, stored_digest = arrays.pop(_KEY_ENTRY, None), arrays.pop(_DIGEST_ENTRY, None)
    if stored_key is None or stored_digest is None:  # older format: nothing vouches for the numbers
        return None
    if str(stored_key) != key or str(stored_digest) != arrays_digest(arrays):
        return None
    return arrays


def store_cached(key: str, arrays: Mapping[str, np.ndarray], directory: str | os.PathLike | None = None) -> Path:
    """Write ``arrays`` under ``key`` atomically; returns the file path."""
    folder = cache_dir(directory)
    folder.mkdir(parents=True, exist_ok=True)
    path = _path(key, folder)
    if {_KEY_ENTRY, _DIGEST_ENTRY} & set(arrays):
        raise ValueError(f"array names {_KEY_ENTRY!r} and {_DIGEST_ENTRY!r} are reserved by the cache; "
                         f"rename that array")
    values = {name: np.asarray(a) for name, a in arrays.items()}
    with atomic_path(path, suffix=".tmp") as tmp, open(tmp, "wb") as stream:
        np.savez(stream, **values, **{_KEY_ENTRY: np.array(key), _DIGEST_ENTRY: np.array(arrays_digest(values))})
    return path


def keep_cached(key: str, arrays: Mapping[str, np.ndarray], directory: str | os.PathLike | None = None) -> Path | None:
    """``store_cached``, except that a folder that cannot be written costs one warning
    line instead of the result: the arrays are then kept in memory for this process
    (``load_cached`` serves them) and None is returned instead of the file path."""
    folder = cache_dir(directory)
    if cache_is_writable(folder):
        try:
            return store_cached(key, arrays, folder)
        except OSError as error:  # full disk, a mount turned read-only, permissions changed
            _mark_unwritable(folder, error)
    _remember(folder, key, arrays)
    return None


def cached(
    parts: Mapping[str, Any],
    compute: Callable[[], Mapping[str, np.ndarray]],
    directory: str | os.PathLike | None = None,
) -> dict[str, np.ndarray]:
    """Arrays for ``parts`` from the cache, or ``compute()`` them and store them (also
    when the stored file is damaged or stale, see ``load_cached``). The folder is checked
    before ``compute`` runs: one that cannot be written is warned about then, and the
    result is returned all the same (``keep_cached``).

    One computation per entry at a time in this process: a thread that asks for an entry another
    thread is computing waits for it and reads its result (two job threads building tied chains
    that share a segment, ``validation.prototype.tied_chains``; a computation that asks for other
    entries nests, as the keys it asks for never ask back). Other processes (Dask workers) may
    compute the same entry at once: the same bits, each written whole (``store_cached``).

    ``compute`` runs on one thread (``fem.solve.one_thread``: PARDISO and BLAS), so an entry
    holds the same bits whichever command, batch or machine's core count computed it: before,
    a chain built alone on both cores and the same chain built beside another came out 1.4e-13
    apart, and a later noise-free run read whichever the cache held first (docs/scale.md,
    "Issue 26, session 36")."""
    key = cache_key(parts)
    cache_is_writable(directory)  # up front: the warning comes before the FEM work, not after it
    found = load_cached(key, directory)
    if found is not None:
        return found
    entry = (str(cache_dir(directory)), key)
    with _LOCK:
        lock = _COMPUTING.setdefault(entry, threading.RLock())
    with lock:
        found = load_cached(key, directory)  # computed by the thread this one waited for
        if found is not None:
            return found
        try:
            from .solve import one_thread

            with one_thread():  # an entry's bits do not depend on the cores it was computed on
                arrays = {name: np.asarray(a) for name, a in compute().items()}
            keep_cached(key, arrays, directory)
        finally:
            with _LOCK:
                if _COMPUTING.get(entry) is lock:  # not a later thread's, after a failed computation
                    del _COMPUTING[entry]
    return arrays
