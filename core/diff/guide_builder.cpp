#include "core/diff/guide_builder.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <chrono>
#include <mutex>
#include "core/diff/terms/seeding.h"
#include "core/guiding/grid.h"
#include "core/guiding/mixture.h"

namespace limn {
namespace {

// The octree's training round (iterative guiding in the manner of Muller et al. 2017's practical
// path guiding; not in the projective-sampling paper): `octree_training` samples per pixel drawn
// from the projective grid (with its direction histogram) and the integrand evaluated at each. A
// sample whose weight f / g is at least kTrainingSelect times the mean weight lies where the grid
// has less than 1 / kTrainingSelect of the density proportional to f: typically on the stretches
// of a narrow feature between the projections, which the octree's leaves there would otherwise
// estimate as empty from a few uniform points. Those samples join the projections as points the
// octree splits at, each adding its value over one finest cell to its leaf's mass
// (core/guiding/octree.h). Measured in docs/reports/projective/README.md.
constexpr double kTrainingSelect = 2.0;

template <typename Integrand>
void training_points(const Scene& scene, const DiffOptions& opt, const Integrand& integrand, const BoundaryGuide& first,
                     tbb::task_arena& arena, std::vector<Vec3>& kept, std::vector<float>& kept_values, std::string& origin) {
  const uint64_t n = uint64_t(opt.octree_training) * uint64_t(scene.camera.width) * uint64_t(scene.camera.height);
  constexpr uint64_t kTrainingTag = 0x747261696e696e67ULL;
  const BoundaryPoints point(opt, n, kTrainingTag);
  std::vector<Vec3> drawn(n);
  std::vector<float> value(n, 0.0f), pdf(n, 0.0f);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<uint64_t>(0, n, 1024), [&](const tbb::blocked_range<uint64_t>& r) {
      for (uint64_t i = r.begin(); i != r.end(); ++i) {
        Pcg32 rng = pixel_rng(mix_bits(opt.seed ^ kTrainingTag), i);
        drawn[i] = first.sample(point(i, rng), &pdf[i]);
        value[i] = integrand(drawn[i]);
      }
    });
  });
  auto valid = [&](uint64_t i) { return std::isfinite(value[i]) && value[i] > 0.0f && pdf[i] > 0.0f; };
  double mean_weight = 0.0;
  for (uint64_t i = 0; i < n; ++i)
    if (valid(i)) mean_weight += double(value[i]) / pdf[i] / double(n);
  size_t valued = 0;
  for (uint64_t i = 0; i < n; ++i) {
    if (!valid(i)) continue;
    ++valued;
    if (double(value[i]) / pdf[i] < kTrainingSelect * mean_weight) continue;
    kept.push_back(drawn[i]);
    kept_values.push_back(value[i]);
  }
  origin += "; trained with " + std::to_string(n) + " samples of the projective grid" +
            (opt.direction_mix > 0.0f ? " and its direction histogram" : "") + " (" + std::to_string(valued) +
            " of non-zero value, " + std::to_string(kept.size()) + " under-sampled ones added to the octree's points)";
}

// The guiding distribution of the indirect term for this call: the path-space baseline grid
// (random points per cell), or projected seeds into a grid (their integrand values) or an octree
// (their positions; leaf masses from uniform samples; by default mixed with the projective grid),
// either projective guide by default mixed with the projections' direction histogram.
void build_guide(const Scene& scene, const IndirectBoundary& ib, const DiffOptions& opt, int max_depth, CallGuide& terms) {
  auto integrand = [&](const Vec3& u) { return ib.guide_value(u); };
  const std::array<int, 3> res = grid_cells(opt);
  if (opt.guiding == "grid" && !opt.projective) {
    terms.guide = std::make_shared<BoundaryGrid>(res, opt.guiding_spp, opt.seed, opt.threads, integrand);
    terms.origin = std::to_string(opt.guiding_spp) + " random points per cell";
    return;
  }
  const Projector projector(scene, ib.space());
  SeedStats st;
  const uint64_t paths = uint64_t(seeds_per_pixel(opt)) * uint64_t(scene.camera.width) * uint64_t(scene.camera.height);
  const std::vector<Projection> seeds =
      projected_seeds(scene, projector, paths, parse_seed_segments(opt.project_seed, scene.source), max_depth, opt.seed, opt.threads, &st);
  std::vector<Vec3> points(seeds.size());
  for (size_t i = 0; i < seeds.size(); ++i) points[i] = seeds[i].u;
  terms.origin = std::to_string(st.paths) + " seed paths (" + opt.project_seed + " segments): " + std::to_string(st.segments) +
                       " segments, " + std::to_string(st.projected) + " projected, " + std::to_string(st.found) + " onto silhouettes";
  // The integrand at every projection: the grid's cell masses, part of the octree's leaf masses.
  std::vector<float> values(points.size(), 0.0f);
  tbb::task_arena arena(opt.threads > 0 ? opt.threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i != r.end(); ++i) values[i] = integrand(points[i]);
    });
  });
  // The projections' values fill a pyramid of grids around the grid's resolution (GridPyramid).
  auto grid = std::make_shared<GridPyramid>(res, opt.grid_octaves, opt.grid_octaves, points, values);
  // The projections' directions alone (DiffOptions::direction_mix): uniform along u.x, so that it
  // covers the edges the projections missed, with coarser levels for the lobes' tails.
  std::shared_ptr<const BoundaryGuide> directions;
  if (opt.direction_mix > 0.0f) {
    const int D = opt.direction_resolution;
    directions = std::make_shared<GridPyramid>(std::array<int, 3>{1, D, D}, opt.direction_octaves, 0, points, values);
  }
  auto with_directions = [&](std::shared_ptr<const BoundaryGuide> g) -> std::shared_ptr<const BoundaryGuide> {
    return directions ? std::make_shared<GuideMixture>(std::move(g), directions, opt.direction_mix) : g;
  };
  const std::shared_ptr<const BoundaryGuide> projective_grid = with_directions(grid);
  if (opt.guiding == "grid") {
    terms.guide = projective_grid;
    return;
  }
  // The training round samples the projective grid with its direction histogram: where that
  // under-samples the integrand is also where the octree's leaves lack the points to split at
  // (torus: true relative variance 44-73 -> 23-26 against drawing from the grid alone).
  std::vector<Vec3> trained;
  std::vector<float> trained_values;
  if (opt.octree_training > 0) training_points(scene, opt, integrand, *projective_grid, arena, trained, trained_values, terms.origin);
  auto octree = std::make_shared<BoundaryOctree>(points, opt.octree, opt.seed, opt.threads, integrand, values, trained, trained_values);
  std::shared_ptr<const BoundaryGuide> guide = octree;
  if (opt.octree_grid_mix > 0.0f) guide = std::make_shared<GuideMixture>(octree, grid, opt.octree_grid_mix);
  terms.guide = with_directions(guide);
}

// The moving geometry's values and bounding-box diagonal (what decides whether a guide is stale).
std::vector<float> moving_geometry(const Scene& scene, const DiffParams& params, float& extent) {
  std::vector<float> g;
  Vec3 lo(kInfinity), hi(-kInfinity);
  for (int si : params.moving_shapes()) scene.shapes[si].visit([&](const auto& geometry) { geometry.geometry_state(g, lo, hi); });
  extent = lo.x <= hi.x ? glm::length(hi - lo) : 0.0f;
  return g;
}

}  // namespace

// Builds the guide, or reuses the cached one (DiffOptions::guide_cache, GuideCache's rules).
CallGuide guide_for_call(const Scene& scene, const DiffParams& params, const IndirectBoundary& ib, const DiffOptions& opt) {
  CallGuide terms;
  GuideCache* cache = opt.guide_refresh > 0 ? opt.guide_cache : nullptr;
  const std::string key = opt.guiding + "|" + (opt.projective ? "p" : "u") + "|" + opt.project_seed + "|" + opt.boundary_parts + "|" +
                          std::to_string(opt.grid_resolution) + "," + std::to_string(opt.grid_octaves) + "|" + std::to_string(opt.guiding_spp) + "|" +
                          std::to_string(seeds_per_pixel(opt)) + "|" +
                          std::to_string(opt.octree.slices) + "," + std::to_string(opt.octree.max_depth) + "," +
                          std::to_string(opt.octree.leaf_samples) + "," + std::to_string(opt.octree.max_leaves) + "," +
                          std::to_string(opt.octree.refine_rounds) + "," + std::to_string(opt.octree.refine_factor) + "," + std::to_string(opt.octree.refine_depth) + "," +
                          std::to_string(opt.octree_grid_mix) + "," + std::to_string(opt.octree_training) + "|" +
                          std::to_string(opt.direction_mix) + "," + std::to_string(opt.direction_resolution) + "," + std::to_string(opt.direction_octaves) + "|" +
                          std::to_string(ib.space().segments().size()) + "|" + std::to_string(opt.max_depth);
  float extent = 0.0f;
  const std::vector<float> geometry = moving_geometry(scene, params, extent);
  // Calls on one scene may run at once (the scene lock is shared): the cache is looked at and
  // replaced under a lock; building happens outside it.
  static std::mutex cache_mutex;
  std::unique_lock<std::mutex> lock(cache_mutex);
  if (cache && cache->guide && cache->key == key && cache->uses < opt.guide_refresh && cache->geometry.size() == geometry.size()) {
    float moved = 0.0f;
    for (size_t i = 0; i < geometry.size(); ++i) moved = std::max(moved, std::abs(geometry[i] - cache->geometry[i]));
    if (moved <= opt.guide_refresh_threshold * std::max(cache->extent, 1e-6f)) {
      terms.guide = cache->guide;
      terms.origin = cache->origin;
      terms.seconds = 0.0;
      cache->uses++;
      cache->reuses++;
      terms.reuse = " (reused: call " + std::to_string(cache->uses) + " of " + std::to_string(opt.guide_refresh) +
                          " since it was built in " + std::to_string(cache->build_seconds) + " s)";
      return terms;
    }
  }
  lock.unlock();
  const auto t0 = std::chrono::steady_clock::now();
  build_guide(scene, ib, opt, effective_max_depth(scene, opt.max_depth), terms);
  terms.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  lock.lock();
  if (cache) {
    *cache = GuideCache{terms.guide, key, terms.origin, geometry, extent, 1, terms.seconds, cache->builds + 1, cache->reuses};
    terms.reuse = " (kept for up to " + std::to_string(opt.guide_refresh) + " calls)";
  }
  return terms;
}

std::shared_ptr<const BoundaryGuide> build_boundary_guide(const Scene& scene, const IndirectBoundary& indirect, const DiffOptions& options,
                                                          std::string* origin) {
  const DiffOptions opt = resolve_options(scene, options);
  if (opt.guiding != "grid" && opt.guiding != "octree")
    throw std::invalid_argument(scene.source + ": build_boundary_guide needs guiding 'grid' or 'octree' (got '" + opt.guiding + "')");
  CallGuide terms;
  build_guide(scene, indirect, opt, effective_max_depth(scene, opt.max_depth), terms);
  if (origin) *origin = terms.origin;
  return terms.guide;
}

}  // namespace limn
