#include "core/diff/diff_options.h"

#include <cmath>
#include <stdexcept>
#include "core/diff/terms/seeding.h"
#include "core/guiding/grid.h"
#include "core/render/integrators/render.h"

namespace limn {
namespace {

// "<source>: <name> must be <rule> (got <value>)" unless ok.
template <typename V>
void require(bool ok, const Scene& scene, const char* name, const std::string& rule, const V& value) {
  if (ok) return;
  std::string got;
  if constexpr (std::is_same_v<V, std::string>) got = "'" + value + "'";
  else got = std::to_string(value);
  throw std::invalid_argument(scene.source + ": " + name + " must be " + rule + " (got " + got + ")");
}

bool in(double v, double lo, double hi) { return v >= lo && v <= hi; }  // false for NaN

}  // namespace

void validate_diff_options(const Scene& scene, const DiffParams& params, const DiffOptions& opt) {
  if (params.empty()) throw std::invalid_argument(scene.source + ": no differentiable parameters (call set_differentiable first)");
  // Terms and sample counts.
  require(opt.spp >= 0, scene, "spp", ">= 0 (0: the scene's sample count)", opt.spp);
  require(opt.spp_interior >= -1, scene, "spp_interior", ">= 0 (-1: spp)", opt.spp_interior);
  require(opt.spp_primary >= -1, scene, "spp_primary", ">= 0 (-1: spp)", opt.spp_primary);
  require(opt.spp_boundary >= -1, scene, "spp_boundary", ">= 0 (-1: spp)", opt.spp_boundary);
  require(in(opt.threads, 0, kMaxThreads), scene, "threads", "in [0, " + std::to_string(kMaxThreads) + "] (0: all cores)", opt.threads);
  // Indirect boundary term: sampling and guides.
  require(opt.boundary_sampler == "independent" || opt.boundary_sampler == "stratified", scene, "boundary_sampler",
          "'independent' or 'stratified'", opt.boundary_sampler);
  require(opt.guiding == "none" || opt.guiding == "grid" || opt.guiding == "octree", scene, "guiding", "'none', 'grid' or 'octree'",
          opt.guiding);
  parse_seed_segments(opt.project_seed, scene.source);
  require(opt.boundary_parts == "both" || opt.boundary_parts == "perimeter" || opt.boundary_parts == "interior", scene, "boundary_parts",
          "'both', 'perimeter' or 'interior'", opt.boundary_parts);
  require(opt.grid_resolution >= 1, scene, "grid_resolution", ">= 1", opt.grid_resolution);
  const std::array<int, 3> cells = grid_cells(opt);
  if (opt.guiding != "none" && size_t(cells[0]) * cells[1] * cells[2] > BoundaryGrid::kMaxCells)
    throw std::invalid_argument(scene.source + ": grid_resolution " + std::to_string(opt.grid_resolution) + " gives " +
                                std::to_string(size_t(cells[0]) * cells[1] * cells[2]) + " grid cells, which exceed the limit of " +
                                std::to_string(BoundaryGrid::kMaxCells));
  require(in(opt.grid_octaves, 0, 8), scene, "grid_octaves", "in [0, 8]", opt.grid_octaves);
  require(opt.guiding_spp >= 1, scene, "guiding_spp", ">= 1", opt.guiding_spp);
  require(opt.guiding_seeds >= 0, scene, "guiding_seeds", ">= 1 (0: the guide's default)", opt.guiding_seeds);
  require(in(opt.octree.slices, 1, 1 << 16), scene, "octree_slices", "in [1, 65536]", opt.octree.slices);
  require(in(opt.octree.max_depth, 0, 12), scene, "octree_max_depth", "in [0, 12]", opt.octree.max_depth);
  require(opt.octree.leaf_samples >= 1, scene, "octree_leaf_samples", ">= 1", opt.octree.leaf_samples);
  require(opt.octree.max_leaves >= size_t(opt.octree.slices), scene, "octree_max_leaves", ">= octree_slices", opt.octree.max_leaves);
  require(in(opt.octree.refine_rounds, 0, 8), scene, "octree_refine_rounds", "in [0, 8]", opt.octree.refine_rounds);
  require(opt.octree.refine_factor > 0.0f && std::isfinite(opt.octree.refine_factor), scene, "octree_refine_factor", "> 0",
          opt.octree.refine_factor);
  require(in(opt.octree_grid_mix, 0.0, 1.0) && opt.octree_grid_mix < 1.0f, scene, "octree_grid_mix", "in [0, 1)", opt.octree_grid_mix);
  require(opt.octree_training >= 0, scene, "octree_training", ">= 0", opt.octree_training);
  require(in(opt.direction_mix, 0.0, 1.0) && opt.direction_mix < 1.0f, scene, "direction_mix", "in [0, 1)", opt.direction_mix);
  require(in(opt.direction_resolution, 1, BoundaryGrid::kMaxResolution), scene, "direction_resolution",
          "in [1, " + std::to_string(BoundaryGrid::kMaxResolution) + "]", opt.direction_resolution);
  require(in(opt.direction_octaves, 0, 8), scene, "direction_octaves", "in [0, 8]", opt.direction_octaves);
  require(opt.guide_refresh >= 0, scene, "guide_refresh", ">= 0 (0: build every call)", opt.guide_refresh);
  require(opt.guide_refresh_threshold >= 0.0f && std::isfinite(opt.guide_refresh_threshold), scene, "guide_refresh_threshold",
          "finite and >= 0", opt.guide_refresh_threshold);
  // Heightfield estimator.
  require(in(opt.heightfield.interval_uniform_share, 0.0, 1.0), scene, "heightfield_interval_mix", "in [0, 1]",
          opt.heightfield.interval_uniform_share);
  require(in(opt.heightfield.theta_subrange_degrees, 0.0, 180.0) && opt.heightfield.theta_subrange_degrees < 180.0f, scene,
          "theta_subrange", "in [0, 180) degrees", opt.heightfield.theta_subrange_degrees);
}

DiffOptions with_sample_counts(const Scene& scene, DiffOptions o) {
  if (o.spp == 0) o.spp = scene.spp;
  for (int* count : {&o.spp_interior, &o.spp_primary, &o.spp_boundary})
    if (*count < 0) *count = o.spp;
  return o;
}

}  // namespace limn
