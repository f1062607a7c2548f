#!/usr/bin/env bash
# Runs every test of limn and ends with one summary line "N passed, N failed":
#   C++ core (doctest), Python package (pytest), Blender add-on in Debian's Blender 3.4 and in the
#   bpy module (Blender 4.5 LTS from PyPI). Installs and builds what is missing first.
set -uo pipefail
cd "$(dirname "$0")"
./bootstrap.sh --bpy || { echo "bootstrap failed"; exit 1; }

RESULTS=build/test-results
rm -rf "$RESULTS" && mkdir -p "$RESULTS"
PY=.venv/bin/python
status=0
suite() {  # suite NAME COMMAND...
  local name=$1; shift
  printf '\n\033[1m== %s ==\033[0m\n' "$name"
  local t0=$SECONDS
  "$@" || status=1
  echo "($name: $((SECONDS - t0)) s)"
}

suite "C++ core (doctest)" build/cpp/limn_tests --reporters=junit --out="$RESULTS/cpp.xml" --no-intro
suite "Python package (pytest)" "$PY" -m pytest -q tests/python --junitxml="$RESULTS/python.xml"
suite "Blender 3.4 add-on (Debian blender)" blender -b --factory-startup -noaudio --python-exit-code 1 \
      --python tests/blender/run.py -- --junitxml="$RESULTS/blender-3.4.xml"
suite "Blender 4.5 LTS add-on (bpy module)" "$PY" tests/blender/run.py --junitxml="$RESULTS/blender-bpy.xml"
suite "Blender 3.4 in a window (Xvfb)" "$PY" -m pytest -q -p no:cacheprovider tests/blender/window --junitxml="$RESULTS/blender-window.xml"

printf '\n'
"$PY" tests/summarize.py "$RESULTS" || status=1
exit $status
