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
# repeat; without one flexcal still installs, but its fTetWild meshes vary from run to run
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
echo "setup: ready (.venv/bin/flexcal)"
