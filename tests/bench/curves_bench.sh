#!/bin/sh
# Error against run time for fibre curves (issue 36), all methods side by side in one interleaved
# run per scene: uniform boundary sampling (full), the path-space baseline grid with 4 and 40
# points per cell (grid, grid10x, "uniform grid 1x and 10x"), the projective grid and the octrees.
# - coil: a coil in front of the projective-sampling paper's reflection test scene (GGX alpha =
#   0.005 plane before a large emitter; the coil is seen only in the reflection), x translation of
#   all control points. Writes docs/reports/curves/coil_reflection.{md,png} (about 15-20 min).
# - shadows: the bent fibre's shadow under a small area light and the yarn (two crossing strands,
#   the upper one shadowing the lower one and the floor), x translation of all control points;
#   the FD reference as two independent halves whose difference gives its own error. Writes
#   docs/reports/curves/{fibre,yarn}_shadow_area.{md,png}.
# Usage: tests/bench/curves_bench.sh [coil|shadows|all] [extra limn bench arguments]
set -e
cd "$(dirname "$0")/../.."
PY=${PY:-.venv/bin/python}
WHICH=${1:-all}
[ $# -gt 0 ] && shift
case "$WHICH" in coil|shadows|all) ;; *) echo "curves_bench.sh: first argument '$WHICH' must be coil, shadows or all" >&2; exit 2;; esac
if [ "$WHICH" = coil ] || [ "$WHICH" = all ]; then
  nice "$PY" -m limn bench scenes/curves/coil_reflection.json --param coil.control_points --tangent x \
    --methods full,grid,grid10x,projective_grid,octree_untrained,octree --budgets 64 256 \
    --fd-spp 16384 --eps 0.005 --runs 2 --out docs/reports/curves "$@"
fi
if [ "$WHICH" = shadows ] || [ "$WHICH" = all ]; then
  for scene in fibre_shadow_area yarn_shadow_area; do
    nice "$PY" -m limn bench scenes/curves/$scene.json --param fibre.control_points --tangent x \
      --methods full,grid,grid10x,projective_grid,octree_untrained --budgets 16 64 \
      --fd-spp 8192 --eps 0.02 --runs 2 --out docs/reports/curves "$@"
  done
fi
