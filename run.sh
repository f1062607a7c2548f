#!/usr/bin/env bash
# The main job: installs what is missing, builds limn, and renders the default scene to EXR and PNG.
set -euo pipefail
cd "$(dirname "$0")"
./bootstrap.sh
mkdir -p out
.venv/bin/python -m limn render scenes/default.json -o out/default.exr "$@"
