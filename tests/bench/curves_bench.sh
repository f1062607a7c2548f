#!/bin/sh
# Error against run time for fibre curves (issue 36): a coil in front of the projective-sampling
# paper's reflection test scene (GGX alpha = 0.005 plane before a large emitter; the coil is seen
# only in the reflection), derivative of an x translation of all control points. Methods side by
# side in one run (interleaved): uniform boundary sampling (full), the path-space baseline grid
# with 4 and 40 points per cell (grid, grid10x), the projective grid, the paper's octree
# (octree_untrained) and limn's default octree. Writes docs/reports/curves/coil_reflection.{md,png}.
# Usage: tests/bench/curves_bench.sh [extra limn bench arguments]   (about 15-20 min on 2 cores)
set -e
cd "$(dirname "$0")/../.."
PY=${PY:-.venv/bin/python}
nice "$PY" -m limn bench scenes/curves/coil_reflection.json --param coil.control_points --tangent x \
  --methods full,grid,grid10x,projective_grid,octree_untrained,octree --budgets 64 256 \
  --fd-spp 16384 --eps 0.005 --runs 2 --out docs/reports/curves "$@"
