#include "core/diff/diff_options.h"

#include <algorithm>
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
  const std::string max_spp = std::to_string(kMaxSpp);
  require(in(opt.spp, 0, kMaxSpp), scene, "spp", "in [0, " + max_spp + "] (0: the scene's sample count)", opt.spp);
  require(in(opt.spp_interior, -1, kMaxSpp), scene, "spp_interior", "in [0, " + max_spp + "] (-1: spp)", opt.spp_interior);
  require(in(opt.spp_primary, -1, kMaxSpp), scene, "spp_primary", "in [0, " + max_spp + "] (-1: spp)", opt.spp_primary);
  require(in(opt.spp_boundary, -1, kMaxSpp), scene, "spp_boundary", "in [0, " + max_spp + "] (-1: spp)", opt.spp_boundary);
  require(in(opt.threads, 0, kMaxThreads), scene, "threads", "in [0, " + std::to_string(kMaxThreads) + "] (0: all cores)", opt.threads);
  // Indirect boundary term: sampling and guides.
  require(opt.boundary_sampler == "independent" || opt.boundary_sampler == "stratified", scene, "boundary_sampler",
          "'independent' or 'stratified'", opt.boundary_sampler);
  require(opt.guiding == "auto" || opt.guiding == "none" || opt.guiding == "grid" || opt.guiding == "octree", scene, "guiding",
          "'auto', 'none', 'grid' or 'octree'", opt.guiding);
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
  // Scene features whose discontinuities no term samples.
  if (params.any_geometry())
    for (const Emitter& e : scene.emitters)
      if (const auto* pt = std::get_if<PointEmitter>(&e.model); pt && pt->hard_edge())
        throw std::invalid_argument(scene.source + ": spot '" + e.id + "' has a hard edge (beam_width = cutoff_angle = " +
                                    std::to_string(pt->cutoff * 180.0f / kPi) +
                                    " degrees), a discontinuity of its lighting that no boundary term samples; give it a soft "
                                    "edge (beam_width < cutoff_angle) to differentiate geometry");
}

// Every boundary segment the indirect term can sample ends at a point or directional light,
// which fixes its direction: no bounce after the first hit, and no emitter of non-zero extent.
// A guide's direction axes then hold nothing, and its seeds find no value (the validation
// scenes' point lights: 0 of 65536 seeds; docs/reports/default_estimator/README.md).
static bool only_delta_light_boundaries(const Scene& scene, const DiffOptions& o) {
  const int depth = scene.integrator.type == "direct" ? 2 : effective_max_depth(scene, o.max_depth);
  if (depth < 0 || depth > 2) return false;
  return std::all_of(scene.emitters.begin(), scene.emitters.end(), [](const Emitter& e) { return e.is_delta(); });
}

DiffOptions resolve_options(const Scene& scene, DiffOptions o) {
  if (o.spp == 0) o.spp = scene.spp;
  for (int* count : {&o.spp_interior, &o.spp_primary, &o.spp_boundary})
    if (*count < 0) *count = o.spp;
  if (o.guiding == "auto" && only_delta_light_boundaries(scene, o)) {
    o.guiding = "none";
    o.guiding_auto = true;
  } else if (o.guiding == "auto") {
    o.guiding = o.spp_boundary >= kAutoOctreeSpp ? "octree" : "grid";
    // Leaves that few of the call's samples land in cost set-up and lower little variance: the
    // octree gets one leaf per 16 boundary samples of the call. On occluder_area's moving floor
    // (16x16, 256 spp) the uncapped octree grew 780k leaves in 22 s for 65536 samples; capped at
    // 4096 its error was the same (0.097 of the gradient's RMS), its set-up 1 s.
    const size_t samples = size_t(scene.camera.width) * size_t(scene.camera.height) * size_t(o.spp_boundary);
    o.octree.max_leaves = std::min(o.octree.max_leaves, std::max(size_t(o.octree.slices), samples / 16));
    o.projective = true;
    o.guiding_auto = true;
  }
  return o;
}

}  // namespace limn
