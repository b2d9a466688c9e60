"""fTetWild in a child process, so that Ctrl-C and SIGTERM work while it meshes.

pytetwild (through fTetWild/geogram) sets the process's SIGINT handler to the system
default at the start of each ``tetrahedralize`` call and leaves it so: Ctrl-C during or
after meshing killed the whole ``flexcal`` process with no message and no clean-up
(measured with pytetwild 0.4.2: ``sigaction(SIGINT)`` reads ``SIG_DFL`` during and after
the call, SIGTERM is left alone). Running the call in a child process keeps the parent's
handlers untouched and lets the parent stop at once: on ``KeyboardInterrupt`` (or any
other exception) while it waits, it kills the child and re-raises. The child also runs in
a fresh temporary folder, where fTetWild writes its ``__tracked_surface.stl``.

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
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["tetrahedralize_in_child"]

_ARRAY_ARGUMENTS = ("vertices", "faces", "bg_vertices", "bg_tets", "bg_values")


def tetrahedralize_in_child(vertices: np.ndarray, faces: np.ndarray, **kwargs: Any) -> tuple[np.ndarray, np.ndarray]:
    """``pytetwild.tetrahedralize(vertices, faces, **kwargs)`` run in a child process.

    Array keyword arguments (``bg_vertices``, ``bg_tets``, ``bg_values``) may be arrays or
    None; the others must be JSON values. Returns (nodes, tets) as numpy arrays. Raises
    RuntimeError with the child's last error line if fTetWild fails; KeyboardInterrupt
    and every other exception raised while waiting stop the child first.
    """
    arrays = {"vertices": np.asarray(vertices), "faces": np.asarray(faces)}
    options = {}
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
            return np.array(data["nodes"]), np.array(data["tets"])


def _main(argv: list[str]) -> int:
    import pytetwild

    inputs, outputs = argv
    with np.load(inputs, allow_pickle=False) as data:
        arrays = {name: np.array(data[name]) for name in data.files}
    options = json.loads(str(arrays.pop("__options__")))
    nodes, tets = pytetwild.tetrahedralize(arrays.pop("vertices"), arrays.pop("faces"), **arrays, **options)
    partial = Path(outputs).with_name("out.partial.npz")
    np.savez(partial, nodes=np.asarray(nodes), tets=np.asarray(tets))
    os.replace(partial, outputs)
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
