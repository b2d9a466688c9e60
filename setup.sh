#!/usr/bin/env bash
# Set up flexcal on a fresh machine: system libraries CadQuery and VTK load, then a
# virtual environment in .venv with flexcal and its test tools. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")"

# CadQuery's OCP loads libGL.so.1 and libX11.so.6; VTK renders off-screen through EGL or
# OSMesa. Install what is missing (Debian/Ubuntu, as root). Elsewhere: install the
# equivalents of libgl1 libx11-6 libegl1 libosmesa6 (and a C compiler) with your package manager.
missing=()
for pkg in libgl1 libx11-6 libegl1 libosmesa6 libxrender1; do
  dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
# a C compiler builds flexcal.fem._entropy (fem/_entropy.c), which makes fTetWild's meshes
# repeat, and flexcal.model._consistent_map (model/_consistent_map.c), the consistent model's map
# on vector lanes; without one flexcal still installs, but its fTetWild meshes vary from run to
# run and the consistent model runs numba's slower copy
command -v cc >/dev/null 2>&1 || missing+=(gcc libc6-dev)
if [ ${#missing[@]} -gt 0 ]; then
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "setup: installing system libraries: ${missing[*]}"
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "setup: warning: missing system libraries ${missing[*]} (need root + apt-get); CadQuery/VTK may fail" >&2
  fi
fi

PYTHON=${PYTHON:-python3.11}
command -v "$PYTHON" >/dev/null 2>&1 || PYTHON=python3
[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -e '.[test]'

# numba compiles the model's kernels on their first call and caches them in model/__pycache__:
# the consistent model's (the calibration default, docs/model.md "Session 20") take ~2-2.5 min
# of CPU, the second-order model's ~0.5 min. Compile them here, on one small batch of each model
# (64 candidates: the batched kernels' size too), so that the first flexcal run does not pay it.
echo "setup: compiling the model's kernels (numba; a few minutes, once)"
.venv/bin/python -c '
import numpy as np
from flexcal.model.forward import forward
from flexcal.model.trajectory import standard_trajectory
from flexcal.validation.runs.model_correction import model_space
for model in ("consistent", "second-order"):
    space = model_space("closed-form", model=model)
    forward(np.repeat(space.nominal_full[None], 64, axis=0), standard_trajectory(space.mechanism, n_points=13).inputs,
            space=space, engine="numba")
'
echo "setup: ready (.venv/bin/flexcal)"
