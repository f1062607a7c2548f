#!/usr/bin/env bash
# The main job: installs what is missing, builds limn, renders the default scene to EXR and PNG, and
# runs the inverse shape optimisation demo (out/demo: result mesh, renders, loss and Chamfer history).
set -euo pipefail
cd "$(dirname "$0")"
./bootstrap.sh
mkdir -p out
.venv/bin/python -m limn render scenes/default.json -o out/default.exr
.venv/bin/python -m limn demo -o out/demo
