#!/usr/bin/env bash
# Set up everything twinkit needs on a fresh Debian/Ubuntu machine with Python 3.11:
# system libraries (as root, through apt), a virtualenv in .venv, twinkit and every plugin in plugins/.
# Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

# 1. System libraries: open3d needs libusb; moderngl's headless EGL (Mesa llvmpipe) needs the EGL/DRI packages;
#    the report's browser tests use Debian's Chromium and ChromeDriver; three.js for the report comes from npm.
APT_PACKAGES=(libusb-1.0-0 libegl1 libegl-mesa0 libgl1-mesa-dri libgomp1 chromium chromium-driver)
command -v npm >/dev/null || APT_PACKAGES+=(nodejs npm)
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then
    echo "setup: installing system packages: ${missing[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  elif command -v sudo >/dev/null; then
    sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "setup: please install these system packages first: ${missing[*]}" >&2
    exit 1
  fi
fi

# 2. A virtualenv with Python 3.11 (bpy 5.0.1 has wheels for 3.11 only).
PYTHON=${PYTHON:-}
if [ -z "$PYTHON" ]; then
  for c in python3.11 python3; do
    if command -v "$c" >/dev/null && "$c" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then PYTHON=$c; break; fi
  done
fi
[ -n "$PYTHON" ] || { echo "setup: twinkit needs Python 3.11 (set PYTHON=/path/to/python3.11)" >&2; exit 1; }
[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
PIP=(.venv/bin/python -m pip install --quiet --disable-pip-version-check)

# 3. PyTorch, CPU build (pinned: a plain 'torch' would pull a multi-GB CUDA build).
.venv/bin/python -c 'import torch' 2>/dev/null || "${PIP[@]}" "torch==2.13.0"

# 4. twinkit and every plugin package in plugins/, editable, so edits take effect at once.
args=(-e .)
for d in plugins/*/; do
  [ -f "$d/pyproject.toml" ] && args+=(-e "$d")
done
# test tools: ruff and mypy are the static checks `make test` runs first (pinned to a minor version, so that their
# rules do not change under the code); plyfile (GPL-3.0) reads twinkit's PLY files back in tests, as an independent
# reader (twinkit itself never imports it: twinkit.mesh.ply reads and writes PLY with numpy); trimesh reads twinkit.mesh's files back in
# tests/mesh and is the baseline of bench/bench_meshio.py (twinkit itself does not import it)
"${PIP[@]}" "${args[@]}" pytest pytest-timeout "ruff~=0.17.6" "mypy~=2.4.1" "plyfile>=1.0" "selenium>=4.20" "trimesh>=4"
# 5. Blender as a module for the FBX exporter. bpy 5.0.1 (wheels for Python 3.11 only) declares numpy<2 but
#    its FBX export runs with numpy 2 (tested), which other plugins need: install it without its pin.
.venv/bin/python -c 'import bpy' 2>/dev/null || {
  "${PIP[@]}" --no-deps "bpy==5.0.1"
  "${PIP[@]}" cython zstandard requests
}
# optional extras whose tests run in CI: Hugging Face models (tested offline with tiny random models),
# the TFLite CityScapes model, and the readers used by the exporters' round-trip tests
"${PIP[@]}" "transformers>=4.40" "ai-edge-litert" "ufbx>=0.0.5" "pygltflib>=1.16"

# 6. The numba loops compiled into their on-disk cache for the argument types a run uses (twinkit.surface.compiled
#    `ahead` marks), so the first run after set-up loads them instead of compiling them (4-5 s on the demo)
.venv/bin/python -m twinkit.surface.compiled

# 7. three.js for the report's 3D view (registry only), bundled once by esbuild into
#    twinkit/report_assets/three-bundle.js, which each report copies (never fetched at view time)
npm ci --no-audit --no-fund --loglevel=error
npm run --silent bundle

echo "setup: done ($(.venv/bin/python --version); $(ls -d plugins/*/ | wc -l) plugin packages)"
