"""fTetWild in a child process, so that Ctrl-C and SIGTERM work while it meshes.

pytetwild (through fTetWild/geogram) sets the process's SIGINT handler to the system
default at the start of each ``tetrahedralize`` call and leaves it so: Ctrl-C during or
after meshing killed the whole ``flexcal`` process with no message and no clean-up
(measured with pytetwild 0.4.2: ``sigaction(SIGINT)`` reads ``SIG_DFL`` during and after
the call, SIGTERM is left alone). Running the call in a child process keeps the parent's
handlers untouched and lets the parent stop at once: on ``KeyboardInterrupt`` (or any
other exception) while it waits, it kills the child and re-raises. The child also runs in
a fresh temporary folder, where fTetWild writes its ``__tracked_surface.stl``.

A child must not outlive the process that started it. A Dask worker ended by its nanny
(Ctrl-C or SIGTERM of a parallel ``flexcal truth``) dies without running its ``finally``
blocks: its child went on meshing for seconds to minutes after the command had stopped,
and its temporary folder stayed in the temporary directory. So, on Linux, the child asks
the kernel to kill it when its parent dies (``prctl(PR_SET_PDEATHSIG, SIGKILL)``; the
"parent" is the thread that started it, which here is the thread that waits for it), and
each temporary folder's name records its owner (``owners.owner_tag``): every later mesh
removes the folders whose owner is gone (``remove_stale_mesher_folders``).

The child also makes the mesh repeat. fTetWild seeds its generator from
``std::random_device`` and pytetwild exposes no seed, so the same input gave a different
mesh on every call. The child loads ``flexcal.fem._entropy`` (``fem/_entropy.c``) into
the global symbol scope before it imports pytetwild; that module serves fTetWild's
``random_device`` draws from a generator restarted at ``seed`` (default
``MESHER_SEED``). The same surface, sizing field and options then give the same mesh, with
any number of threads. If the module was not built (no C compiler at install) or
fTetWild drew nothing through it, the mesh comes out unseeded and a ``RuntimeWarning``
says so.

The price is one interpreter start and the pytetwild import per mesh (0.28-0.31 s wall,
0.35-0.40 s CPU on the idle 2-core development machine, five runs; a few seconds when it
is heavily loaded), small against the seconds to minutes a mesh and its solve take.

``python -m flexcal.fem.tetwild_process IN.npz OUT.npz [PARENT_PID]`` is the child's side: it reads
the arrays and keyword arguments of ``pytetwild.tetrahedralize`` from IN.npz and writes
``nodes`` and ``tets`` to OUT.npz (whole: temporary name, then rename).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from flexcal.geometry.atomic import atomic_path

from .owners import OWNER_TAG, owner_tag, remove_folders_of_gone_owners

__all__ = ["MESHER_SEED", "RUNAWAY_FACTOR", "SEED_TRIES", "expected_vertices", "mesher_is_seeded",
           "remove_stale_mesher_folders", "runs_away", "tetrahedralize_in_child"]

MESHER_SEED = 20240523  # any fixed value serves; changing it changes every fTetWild mesh
SEED_TRIES = 3  # seeds tried in turn when a run runs away (runs_away)
RUNAWAY_FACTOR = 25.0  # vertex count / the sizing field's expected count that stops a run (runs_away)

_ARRAY_ARGUMENTS = ("vertices", "faces", "bg_vertices", "bg_tets", "bg_values")
# a child's temporary folder: flexcal-tetwild-HOST-PID-START-XXXXXXXX (the owner's tag, then
# tempfile's 8 random characters)
_FOLDER_PREFIX = "flexcal-tetwild-"
_FOLDER_NAME = re.compile(rf"^{_FOLDER_PREFIX}{OWNER_TAG}-[a-z0-9_]{{8}}$")
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def remove_stale_mesher_folders(folder: str | os.PathLike | None = None) -> list[str]:
    """Remove the children's temporary folders in ``folder`` (default: the temporary
    directory) whose owner process is gone; returns their names (``owners``)."""
    return remove_folders_of_gone_owners(tempfile.gettempdir() if folder is None else folder, _FOLDER_NAME)


def mesher_is_seeded() -> bool:
    """True if the fixed entropy source ``flexcal.fem._entropy`` is built and importable."""
    import importlib.util

    return importlib.util.find_spec("flexcal.fem._entropy") is not None


def tetrahedralize_in_child(vertices: np.ndarray, faces: np.ndarray, *, seed: int = MESHER_SEED,
                            **kwargs: Any) -> tuple[np.ndarray, np.ndarray]:
    """``pytetwild.tetrahedralize(vertices, faces, **kwargs)`` run in a child process,
    fTetWild's ``random_device`` restarted at ``seed`` (a non-negative integer); if that
    run runs away (``runs_away``; watched when a sizing field ``bg_*`` is given), again at
    seed + 1, then seed + 2.

    Array keyword arguments (``bg_vertices``, ``bg_tets``, ``bg_values``) may be arrays or
    None; the others must be JSON values (``quiet`` and ``loglevel`` are the child's: it
    reports its passes to this process). Returns (nodes, tets) as numpy arrays. Raises
    RuntimeError with the child's last error line if fTetWild fails, or if every seed ran
    away; KeyboardInterrupt and every other exception raised while waiting stop the child
    first. Warns (RuntimeWarning) if the mesh could not be seeded.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**64 - SEED_TRIES:
        raise ValueError(f"seed={seed!r} must be an integer in [0, 2**64 - {SEED_TRIES})")
    arrays = {"vertices": np.asarray(vertices), "faces": np.asarray(faces)}
    options = {name: value for name, value in kwargs.items()
               if name not in _ARRAY_ARGUMENTS and name not in ("quiet", "loglevel")}
    arrays.update({name: np.asarray(value) for name, value in kwargs.items()
                   if name in _ARRAY_ARGUMENTS and value is not None})
    has_field = all(name in arrays for name in ("bg_vertices", "bg_tets", "bg_values"))
    expected = expected_vertices(arrays["bg_vertices"], arrays["bg_tets"], arrays["bg_values"]) if has_field else None
    for attempt in range(SEED_TRIES):
        result = _mesh_in_child(arrays, {**options, "__seed__": int(seed) + attempt}, expected)
        if result is not None:
            break
    else:
        raise RuntimeError(f"fTetWild's mesh kept growing with seeds {seed} to {int(seed) + SEED_TRIES - 1} "
                           "(runs_away); try other mesh settings (elements through the thickness, epsilon)")
    nodes, tets, draws = result
    if draws <= 0:
        reason = ("flexcal.fem._entropy is not built (no C compiler when flexcal was installed; "
                  "install gcc and reinstall)" if draws < 0 else
                  "fTetWild drew nothing through flexcal.fem._entropy (another pytetwild build?)")
        warnings.warn(f"fTetWild ran unseeded: {reason}; its meshes differ from run to run",
                      RuntimeWarning, stacklevel=2)
    return nodes, tets


def expected_vertices(bg_vertices: np.ndarray, bg_tets: np.ndarray, bg_values: np.ndarray) -> float:
    """The sizing field's own vertex count: sum over its tets of volume / h^3 (h the mean
    target edge length at the tet's corners). fTetWild's vertex counts on the mount's
    segments (its largest, printed after each operation) were 5.4-8.9x this."""
    a, b, c, d = (bg_vertices[bg_tets[:, k]] for k in range(4))
    volume = np.abs(np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)) / 6.0
    return float(np.sum(volume / np.mean(bg_values[bg_tets], axis=1) ** 3))


def runs_away(vertex_count: int, expected: float) -> bool:
    """True once fTetWild's vertex count (printed after each operation of its optimization
    passes) exceeds ``RUNAWAY_FACTOR`` x the sizing field's ``expected_vertices``.

    fTetWild refines its sizing field where it cannot bring the worst element under its
    stop energy; in rare runs that never succeeds and the mesh grows pass after pass up to
    its 80 passes. Measured on a 36 mm block segment of the mount (expected 2 858): with
    MESHER_SEED ~6k vertices at pass 20, 19.5k at pass 28, 52k a few passes later, still
    meshing after 17 min; seeds 1, 2, 3 finished in 18 / 6.6 / 8.0 s. Normal runs on the
    mount's leaf, block and strut segments peaked at 5.4-8.9x expected; 25x leaves 2.8x
    room above that and stops a runaway after a few more doublings. It counts vertices,
    not seconds, so the outcome does not depend on the machine's speed."""
    return vertex_count > RUNAWAY_FACTOR * expected


def _mesh_in_child(arrays: dict[str, np.ndarray], options: dict[str, Any], expected: float | None) -> tuple | None:
    """One child run: (nodes, tets, draws), or None if it ran away (child stopped; watched
    only when ``expected``, the sizing field's vertex count, is given)."""
    remove_stale_mesher_folders()
    with tempfile.TemporaryDirectory(prefix=f"{_FOLDER_PREFIX}{owner_tag()}-") as folder:
        inputs, outputs, errors = Path(folder) / "in.npz", Path(folder) / "out.npz", Path(folder) / "stderr.txt"
        np.savez(inputs, __options__=np.array(json.dumps(options)), **arrays)
        with open(errors, "wb") as stderr:
            # Popen and the waiting below must stay in one thread: the child dies with it (_die_with_parent)
            child = subprocess.Popen([sys.executable, "-m", __name__, str(inputs), str(outputs), str(os.getpid())],
                                     cwd=folder, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=stderr)
            try:
                for line in child.stdout:
                    if expected is not None and line.startswith(b"#v = ") and runs_away(int(line[5:]), expected):
                        child.kill()
                        child.wait()
                        return None
                child.wait()
            except BaseException:
                child.kill()
                child.wait()
                raise
            finally:
                child.stdout.close()
        if child.returncode != 0 or not outputs.is_file():
            lines = [line for line in errors.read_text(errors="replace").splitlines() if line.strip()]
            reason = lines[-1].strip() if lines else f"exit status {child.returncode}"
            raise RuntimeError(f"fTetWild failed ({reason}); try other mesh settings (elements through "
                               f"the thickness, epsilon)")
        with np.load(outputs, allow_pickle=False) as data:
            return np.array(data["nodes"]), np.array(data["tets"]), int(data["draws"])


def _load_entropy_globally() -> Any:
    """Import ``flexcal.fem._entropy`` into the global symbol scope (RTLD_GLOBAL), where
    the dynamic linker finds its ``random_device`` before pytetwild's libstdc++ one.
    Must run before pytetwild is imported. None if the module is not built."""
    flags = sys.getdlopenflags()
    sys.setdlopenflags(flags | os.RTLD_GLOBAL)
    try:
        from flexcal.fem import _entropy
    except ImportError:
        return None
    finally:
        sys.setdlopenflags(flags)
    return _entropy


def _line_buffered_c_stdout() -> None:
    """C stdio's stdout line by line (fTetWild writes through it; on a pipe it would
    otherwise come in 4 KB blocks, passes late)."""
    import ctypes

    libc = ctypes.CDLL(None)
    libc.setvbuf(ctypes.c_void_p.in_dll(libc, "stdout"), None, 1, 0)  # 1: _IOLBF


def _die_with_parent(parent: int) -> None:
    """Linux: have the kernel kill this process (SIGKILL) when the thread that started it
    ends; exit at once if the parent ``parent`` (its process id) is already gone."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:  # it died before the prctl: this process now belongs to init
        os._exit(1)


def _main(argv: list[str]) -> int:
    inputs, outputs, *parent = argv
    if parent:
        _die_with_parent(int(parent[0]))
    entropy = _load_entropy_globally()
    import pytetwild

    with np.load(inputs, allow_pickle=False) as data:
        arrays = {name: np.array(data[name]) for name in data.files}
    options = json.loads(str(arrays.pop("__options__")))
    seed = options.pop("__seed__")
    if entropy is not None:
        entropy.seed(seed)
    _line_buffered_c_stdout()  # the parent reads fTetWild's "#v = N" lines as they come
    nodes, tets = pytetwild.tetrahedralize(arrays.pop("vertices"), arrays.pop("faces"), **arrays, **options,
                                           quiet=False, loglevel=3)
    draws = entropy.draws() if entropy is not None else -1
    with atomic_path(outputs) as partial:  # the parent never reads half a file
        np.savez(partial, nodes=np.asarray(nodes), tets=np.asarray(tets), draws=np.int64(draws))
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
