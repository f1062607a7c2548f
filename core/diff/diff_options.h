// Options of render_forward / render_backward (core/diff/render_diff.h): which terms, how many
// samples, and how the indirect boundary term is guided. The defaults stated here are the only
// ones, and validate_diff_options() the only checks: the Python layer reads the defaults
// (limn._core.diff_option_defaults), forwards user values under the same names, and shows the
// defaults in Scene.render_forward's docstring.
#pragma once
#include <algorithm>
#include <array>
#include <functional>
#include <string>
#include <vector>
#include "core/diff/ad/diff_params.h"
#include "core/diff/estimators/heightfield.h"
#include "core/guiding/octree.h"

namespace limn {

struct GuideCache;  // core/diff/guide_builder.h

// Default seed paths per pixel of the projective guides (docs/reports/projective/README.md). The
// grid takes an eighth of the boundary budget, between kGridSeeds and kGridSeedsMax, so that its
// set-up stays a small share of the call: at 8 spp per optimisation step 32 seeds already cost
// more than the render, while at 1024 spp 128 seeds lower the error (sphere 0.25 -> 0.081, cube
// with a hole 0.30 -> 0.16) at equal time. The octree only splits at projections of non-zero value
// (about 4 % of them in the paper's test scene), so it needs more.
constexpr int kGridSeeds = 32;
constexpr int kGridSeedsMax = 128;
constexpr int kOctreeSeeds = 256;
// Default training samples per pixel of the octree's training round (render_diff.cpp,
// training_points; docs/reports/projective/README.md).
constexpr int kOctreeTraining = 512;
// The projective guides' direction histogram (DiffOptions::direction_mix): near-specular chains
// put every silhouette edge's integrand into a narrow peak around nearly the same directions
// (towards the camera's mirror image), so directions learnt on the edges the projections found
// also cover the peaks of the edges they missed, which the grid's and the octree's cells there
// hold at the defensive density only (bunny: weights up to 1e7 times the mean, one render in
// about six off by 10x the reference's RMS). docs/reports/projective/README.md.
constexpr float kDirectionMix = 0.2f;
constexpr int kDirectionResolution = 256;
// Coarser direction histograms (GridPyramid levels D/2, D/4) beside the D x D one: the GGX lobe's
// tails reach past the cells the projections filled, where the finest histogram drops by 1000x
// (bunny, the worst sample of a 1024-spp render: f / p 3.6e7 -> 7e4 on its edge; 16 runs: octree
// RMSE 0.138 -> 0.064). docs/reports/projective/README.md.
constexpr int kDirectionOctaves = 2;
// The projective grid's pyramid (core/guiding/grid.h, GridPyramid): grids from R/4 to 4R cells
// along each axis; docs/reports/projective/README.md.
constexpr int kGridOctaves = 2;
// guiding "auto": the octree from this many boundary samples per pixel, the projective grid below
// (docs/reports/default_estimator/README.md): the octree's error is lower per sample, but its set-up costs
// seconds where the grid's costs a tenth of that, which decides at low budgets.
constexpr int kAutoOctreeSpp = 256;
// Calls a guide is kept for by default (guide_refresh), while the geometry moves less than
// guide_refresh_threshold of its size: optimisation steps and repeated calls reuse it.
constexpr int kGuideRefresh = 8;

struct DiffOptions {
  int spp = 0;            // samples per pixel of every term that does not set its own (0: the scene's sample count)
  int spp_interior = -1;  // interior-term paths per pixel (-1: spp; 0: off)
  int spp_primary = -1;   // primary-visibility boundary samples, per pixel on average (-1: spp; 0: off)
  int spp_boundary = -1;  // indirect boundary samples, per pixel on average (-1: spp; 0: off)
  // Indirect boundary: the call's points of [0,1)^3 "independent" or "stratified" (core/math/sequence.h).
  std::string boundary_sampler = "stratified";
  // Indirect boundary: which parts of Eq. 4 to sample, "both", "perimeter" (edges, creases) or
  // "interior" (curved surfaces); one part alone validates it against finite differences.
  std::string boundary_parts = "both";
  // Indirect boundary: "auto" (the projective grid, or the octree from kAutoOctreeSpp samples per
  // pixel), "none" (uniform), "grid" or "octree" (core/guiding/).
  std::string guiding = "auto";
  bool guiding_auto = false;     // set by resolve_options: guiding was "auto" (the summary says so)
  bool projective = true;        // grid: fill from projected seeds (false: the path-space baseline)
  std::string project_seed = "both";  // seed segments from "bsdf", "emitter" or "both" (core/diff/seeding.h)
  int grid_resolution = 64;      // grid cells along the first axis; (R/4, R/2) along the direction axes
  // Projective grid: a pyramid of grids at R 2^k cells (and R/4 2^k, R/2 2^k), k = -grid_octaves
  // .. grid_octaves, filled from the same projections (GridPyramid); 0: one grid, as in the paper.
  int grid_octaves = kGridOctaves;
  int guiding_spp = 4;           // baseline grid: random points per cell
  // Projective guides: seed paths per pixel; 0 picks the guide's default (seeds_per_pixel).
  int guiding_seeds = 0;
  OctreeOptions octree;
  // Octree guiding: the share of the projective grid, filled from the same projections, in the
  // sampling mixture (core/guiding/mixture.h); 0 samples the octree alone.
  float octree_grid_mix = 0.5f;
  // Octree guiding: samples per pixel drawn from the projective grid (with its direction histogram)
  // whose under-sampled ones join the projections as the octree's points (render_diff.cpp,
  // training_points); 0: projections only.
  int octree_training = kOctreeTraining;
  // Projective guides: the share of the projections' direction histogram in the sampling mixture
  // (a projective grid of 1 x D x D cells over (u.y, u.z), D = direction_resolution, uniform along
  // the segments' axis u.x; render_diff.cpp, build_guide); 0: off.
  float direction_mix = kDirectionMix;
  int direction_resolution = kDirectionResolution;
  int direction_octaves = kDirectionOctaves;  // coarser histograms beside it (GridPyramid levels)
  GuideCache* guide_cache = nullptr;  // where guides are kept between calls (null: rebuilt every call)
  int guide_refresh = kGuideRefresh;  // rebuild after this many calls (0: every call); needs guide_cache
  float guide_refresh_threshold = 0.02f;
  HeightfieldOptions heightfield;  // scenes with a heightfield and differentiable geometry
  int max_depth = kSceneMaxDepth;  // path integrator: overrides the scene's max_depth for every term
  // Interior term: the boundary term of smooth shading's geometric horizon at smooth-shaded,
  // reflective vertices (core/diff/terms/interior.cpp, horizon_term); false leaves it out.
  bool shading_horizon = true;
  uint64_t seed = 0;
  int threads = 0;
  std::function<bool(float)> progress;
};
// The grid guides' cells: grid_resolution along the segments' axis, a quarter and a half of it
// along the two direction axes.
inline std::array<int, 3> grid_cells(const DiffOptions& o) {
  const int R = o.grid_resolution;
  return {R, std::max(1, R / 4), std::max(1, R / 2)};
}
inline int seeds_per_pixel(const DiffOptions& o) {
  if (o.guiding_seeds > 0) return o.guiding_seeds;
  if (o.guiding == "octree") return kOctreeSeeds;
  return std::clamp(o.spp_boundary / 8, kGridSeeds, kGridSeedsMax);
}


struct DiffStats {
  double seconds = 0.0;
  uint64_t paths = 0, rays = 0;
  uint64_t invalid_paths = 0;   // non-finite values or derivatives, dropped
  std::vector<std::string> summary;  // what was computed and what was left out, and why
};

// Throws std::invalid_argument naming the scene, the option (its Python keyword) and the bad value.
void validate_diff_options(const Scene& scene, const DiffParams& params, const DiffOptions& options);

// The options as a call uses them: spp from the scene when 0, each term's count from spp when -1,
// guiding "auto" resolved.
DiffOptions resolve_options(const Scene& scene, DiffOptions options);

}  // namespace limn
