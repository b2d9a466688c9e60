"""fTetWild in a child process, so that Ctrl-C and SIGTERM work while it meshes.

pytetwild (through fTetWild/geogram) sets the process's SIGINT handler to the system
default at the start of each ``tetrahedralize`` call and leaves it so: Ctrl-C during or
after meshing killed the whole ``flexcal`` process with no message and no clean-up
(measured with pytetwild 0.4.2: ``sigaction(SIGINT)`` reads ``SIG_DFL`` during and after
the call, SIGTERM is left alone). Running the call in a child process keeps the parent's
handlers untouched and lets the parent stop at once: on ``KeyboardInterrupt`` (or any
other exception) while it waits, it kills the child and re-raises. The child also runs in
a fresh temporary folder, where fTetWild writes its ``__tracked_surface.stl``.

The child also makes the mesh repeat. fTetWild seeds its generator from
``std::random_device`` and pytetwild exposes no seed, so the same input gave a different
mesh on every call. The child loads ``flexcal.fem._entropy`` (``fem/_entropy.c``) into
the global symbol scope before it imports pytetwild; that module serves fTetWild's
``random_device`` draws from a generator restarted at ``seed`` (default
``MESHER_SEED``). The same surface, sizing field and options then give the same mesh, with
any number of threads. If the module was not built (no C compiler at install) or
fTetWild drew nothing through it, the mesh comes out unseeded and a ``RuntimeWarning``
says so.

The price is one interpreter start and the pytetwild import per mesh (0.5-0.6 s on the
idle development machine, a few seconds when it is heavily loaded), small against the
seconds to minutes a mesh and its solve take.

``python -m flexcal.fem.tetwild_process IN.npz OUT.npz`` is the child's side: it reads
the arrays and keyword arguments of ``pytetwild.tetrahedralize`` from IN.npz and writes
``nodes`` and ``tets`` to OUT.npz (whole: temporary name, then rename).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["MESHER_SEED", "mesher_is_seeded", "tetrahedralize_in_child"]

MESHER_SEED = 20240523  # any fixed value serves; changing it changes every fTetWild mesh

_ARRAY_ARGUMENTS = ("vertices", "faces", "bg_vertices", "bg_tets", "bg_values")


def mesher_is_seeded() -> bool:
    """True if the fixed entropy source ``flexcal.fem._entropy`` is built and importable."""
    import importlib.util

    return importlib.util.find_spec("flexcal.fem._entropy") is not None


def tetrahedralize_in_child(vertices: np.ndarray, faces: np.ndarray, *, seed: int = MESHER_SEED,
                            **kwargs: Any) -> tuple[np.ndarray, np.ndarray]:
    """``pytetwild.tetrahedralize(vertices, faces, **kwargs)`` run in a child process,
    fTetWild's ``random_device`` restarted at ``seed`` (a non-negative integer).

    Array keyword arguments (``bg_vertices``, ``bg_tets``, ``bg_values``) may be arrays or
    None; the others must be JSON values. Returns (nodes, tets) as numpy arrays. Raises
    RuntimeError with the child's last error line if fTetWild fails; KeyboardInterrupt
    and every other exception raised while waiting stop the child first. Warns
    (RuntimeWarning) if the mesh could not be seeded.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**64:
        raise ValueError(f"seed={seed!r} must be an integer in [0, 2**64)")
    arrays = {"vertices": np.asarray(vertices), "faces": np.asarray(faces)}
    options = {"__seed__": int(seed)}
    for name, value in kwargs.items():
        if name in _ARRAY_ARGUMENTS:
            if value is not None:
                arrays[name] = np.asarray(value)
        else:
            options[name] = value
    with tempfile.TemporaryDirectory(prefix="flexcal-tetwild-") as folder:
        inputs, outputs = Path(folder) / "in.npz", Path(folder) / "out.npz"
        np.savez(inputs, __options__=np.array(json.dumps(options)), **arrays)
        child = subprocess.Popen([sys.executable, "-m", __name__, str(inputs), str(outputs)], cwd=folder,
                                 stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            _, stderr = child.communicate()
        except BaseException:
            child.kill()
            child.wait()
            raise
        if child.returncode != 0 or not outputs.is_file():
            lines = [line for line in stderr.decode(errors="replace").splitlines() if line.strip()]
            reason = lines[-1].strip() if lines else f"exit status {child.returncode}"
            raise RuntimeError(f"fTetWild failed ({reason}); try other mesh settings (elements through "
                               f"the thickness, epsilon)")
        with np.load(outputs, allow_pickle=False) as data:
            nodes, tets, draws = np.array(data["nodes"]), np.array(data["tets"]), int(data["draws"])
    if draws <= 0:
        reason = ("flexcal.fem._entropy is not built (no C compiler when flexcal was installed; "
                  "install gcc and reinstall)" if draws < 0 else
                  "fTetWild drew nothing through flexcal.fem._entropy (another pytetwild build?)")
        warnings.warn(f"fTetWild ran unseeded: {reason}; its meshes differ from run to run",
                      RuntimeWarning, stacklevel=2)
    return nodes, tets


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


def _main(argv: list[str]) -> int:
    entropy = _load_entropy_globally()
    import pytetwild

    inputs, outputs = argv
    with np.load(inputs, allow_pickle=False) as data:
        arrays = {name: np.array(data[name]) for name in data.files}
    options = json.loads(str(arrays.pop("__options__")))
    seed = options.pop("__seed__")
    if entropy is not None:
        entropy.seed(seed)
    nodes, tets = pytetwild.tetrahedralize(arrays.pop("vertices"), arrays.pop("faces"), **arrays, **options)
    draws = entropy.draws() if entropy is not None else -1
    partial = Path(outputs).with_name("out.partial.npz")
    np.savez(partial, nodes=np.asarray(nodes), tets=np.asarray(tets), draws=np.int64(draws))
    os.replace(partial, outputs)
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
