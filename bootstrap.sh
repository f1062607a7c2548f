#!/usr/bin/env bash
# Installs what is missing on a Debian 12 machine and builds limn. Idempotent and quick when
# everything is already there. Used by run.sh and test.sh; safe to call on its own.
#   ./bootstrap.sh          system packages, .venv with limn installed, C++ tests, Blender add-on bundle
#   ./bootstrap.sh --bpy    also the `bpy` module (Blender LTS from PyPI) into .venv, for the add-on tests
set -euo pipefail
cd "$(dirname "$0")"
ROOT=$(pwd)
WITH_BPY=0
[ "${1:-}" = "--bpy" ] && WITH_BPY=1
BPY_VERSION=4.5.15   # newest Blender LTS on PyPI with wheels for CPython 3.11 (Debian 12's Python)

say() { printf '\033[1m[bootstrap]\033[0m %s\n' "$*"; }
# Runs a command quietly; on failure prints its whole output and stops.
LOG=$(mktemp)
trap 'rm -f "$LOG"' EXIT
quiet() { "$@" >"$LOG" 2>&1 || { cat "$LOG"; say "failed: $*"; exit 1; }; }

# --- 1. Debian packages --------------------------------------------------------------------------
PACKAGES=(build-essential cmake ninja-build pkg-config libembree-dev libopenimageio-dev openimageio-tools
          libopenexr-dev libglm-dev doctest-dev libtbb-dev libeigen3-dev nlohmann-json3-dev
          python3 python3-dev python3-venv python3-pip python3-numpy python3-pytest python3-matplotlib python3-skimage blender
          clang-14 libclang-rt-14-dev xvfb xauth imagemagick xdotool)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  say "installing Debian packages: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# --- 2. Python environment: a venv of Debian's /usr/bin/python3, the interpreter Blender embeds ----
if [ ! -x .venv/bin/python ]; then
  say "creating .venv from /usr/bin/python3"
  /usr/bin/python3 -m venv --system-site-packages .venv
fi
PY="$ROOT/.venv/bin/python"
quiet "$PY" -m pip install -q --upgrade "scikit-build-core>=0.8" "pybind11>=2.10"
if [ "$WITH_BPY" = 1 ] && ! "$PY" -c "import bpy, sys; sys.exit(0 if bpy.app.version_string.startswith('${BPY_VERSION%.*}') else 1)" 2>/dev/null; then
  say "installing bpy==$BPY_VERSION (Blender as a Python module) into .venv"
  quiet "$PY" -m pip install -q "bpy==$BPY_VERSION"
fi

# --- 3. Build: the Python package (scikit-build-core) and the doctest suite -----------------------
say "building the limn Python package"
quiet "$PY" -m pip install -q --no-build-isolation --no-deps .
quiet cmake -S . -B build/cpp -G Ninja -DCMAKE_BUILD_TYPE=Release -DLIMN_TESTS=ON -DLIMN_PYTHON=OFF
say "building the C++ tests and the guide-variance tool"
quiet ninja -C build/cpp limn_tests limn_guide_variance

# --- 4. Blender add-on bundle with the compiled module inside (build/addon, build/limn_blender.zip) -
quiet "$PY" blender_addon/package.py --out build
say "ready: .venv (limn $("$PY" -c 'import limn; print(limn.__version__)')), build/cpp/limn_tests, build/cpp/limn_guide_variance, build/addon/limn_blender"
