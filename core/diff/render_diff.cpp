#include "core/diff/render_diff.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <atomic>
#include <chrono>
#include <mutex>
#include "core/diff/interior.h"
#include "core/diff/indirect.h"
#include "core/diff/primary.h"
#include "core/diff/seeding.h"
#include "core/guiding/grid.h"
#include "core/guiding/mixture.h"
#include "core/math/sequence.h"

namespace limn {
namespace {

// Per-thread sums of n doubles, each thread's buffer made on its first use (no exemplar copied
// into every thread) and reduced into the first buffer: for a 2048^2 heightfield the gradient has
// 4M slots, and the copies and an extra total cost about as much as the samples of a small film.
class ThreadSums {
 public:
  explicit ThreadSums(size_t n) : m_n(n), m_local([n] { return std::vector<double>(n, 0.0); }) {}
  std::vector<double>& local() { return m_local.local(); }
  std::vector<double> reduce() {
    auto it = m_local.begin();
    if (it == m_local.end()) return std::vector<double>(m_n, 0.0);
    std::vector<double> total = std::move(*it);
    for (++it; it != m_local.end(); ++it)
      for (size_t i = 0; i < m_n; ++i) total[i] += (*it)[i];
    return total;
  }

 private:
  size_t m_n;
  tbb::enumerable_thread_specific<std::vector<double>> m_local;
};

// Runs `per_path(x, y, rng)` for spp paths in every pixel over tiles, with progress and cancel.
template <typename PerPixel>
void for_each_pixel(const Scene& scene, const DiffOptions& opt, PerPixel&& per_pixel) {
  const int W = scene.camera.width, H = scene.camera.height;
  constexpr int kTile = 16;
  const int tiles_x = (W + kTile - 1) / kTile, tiles_y = (H + kTile - 1) / kTile, tile_count = tiles_x * tiles_y;
  std::atomic<int> done{0};
  std::atomic<bool> cancelled{false};
  std::mutex progress_mutex;
  tbb::task_arena arena(opt.threads > 0 ? opt.threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, tile_count, 1), [&](const tbb::blocked_range<int>& r) {
      for (int tile = r.begin(); tile != r.end(); ++tile) {
        if (cancelled) return;
        const int x0 = (tile % tiles_x) * kTile, y0 = (tile / tiles_x) * kTile;
        for (int y = y0; y < std::min(y0 + kTile, H); ++y)
          for (int x = x0; x < std::min(x0 + kTile, W); ++x) per_pixel(x, y);
        const int d = ++done;
        if (opt.progress && progress_mutex.try_lock()) {
          std::lock_guard<std::mutex> lock(progress_mutex, std::adopt_lock);
          if (!opt.progress(float(d) / tile_count)) cancelled = true;
        }
      }
    });
  });
  if (cancelled) throw RenderCancelled();
}

int interior_spp(const Scene& scene, const DiffOptions& opt) { return opt.spp_interior < 0 ? scene.spp : opt.spp_interior; }

void validate(const Scene& scene, const DiffParams& params, const DiffOptions& opt) {
  if (params.empty()) throw std::invalid_argument(scene.source + ": no differentiable parameters (call set_differentiable first)");
  if (opt.boundary_sampler != "independent" && opt.boundary_sampler != "stratified")
    throw std::invalid_argument(scene.source + ": boundary_sampler must be 'independent' or 'stratified' (got '" + opt.boundary_sampler + "')");
  if (opt.guiding != "none" && opt.guiding != "grid" && opt.guiding != "octree")
    throw std::invalid_argument(scene.source + ": guiding must be 'none', 'grid' or 'octree' (got '" + opt.guiding + "')");
  parse_seed_segments(opt.project_seed, scene.source);
  if (!(opt.octree_grid_mix >= 0.0f && opt.octree_grid_mix < 1.0f))
    throw std::invalid_argument(scene.source + ": octree_grid_mix must be in [0, 1) (got " + std::to_string(opt.octree_grid_mix) + ")");
  if (!(opt.direction_mix >= 0.0f && opt.direction_mix < 1.0f))
    throw std::invalid_argument(scene.source + ": direction_mix must be in [0, 1) (got " + std::to_string(opt.direction_mix) + ")");
  if (opt.direction_octaves < 0 || opt.direction_octaves > 8)
    throw std::invalid_argument(scene.source + ": direction_octaves must be in [0, 8] (got " + std::to_string(opt.direction_octaves) + ")");
  if (opt.direction_resolution < 1 || opt.direction_resolution > BoundaryGrid::kMaxResolution)
    throw std::invalid_argument(scene.source + ": direction_resolution must be in [1, " + std::to_string(BoundaryGrid::kMaxResolution) +
                                "] (got " + std::to_string(opt.direction_resolution) + ")");
  const std::array<int, 3> cells = grid_cells(opt);
  if (opt.guiding != "none" && (opt.grid_resolution < 1 || size_t(cells[0]) * cells[1] * cells[2] > BoundaryGrid::kMaxCells))
    throw std::invalid_argument(scene.source + ": grid_resolution " + std::to_string(opt.grid_resolution) + " gives " +
                                std::to_string(size_t(cells[0]) * cells[1] * cells[2]) + " grid cells, which exceed the limit of " +
                                std::to_string(BoundaryGrid::kMaxCells));
  if (opt.grid_octaves < 0 || opt.grid_octaves > 8)
    throw std::invalid_argument(scene.source + ": grid_octaves must be in [0, 8] (got " + std::to_string(opt.grid_octaves) + ")");
  if (opt.octree_training < 0)
    throw std::invalid_argument(scene.source + ": octree_training must be >= 0 (got " + std::to_string(opt.octree_training) + ")");
  if (opt.guiding_spp < 1 || opt.guiding_seeds < 0)
    throw std::invalid_argument(scene.source + ": guiding_spp must be >= 1 and guiding_seeds >= 0 (0: the guide's default)");
  if (opt.spp_boundary < 0 || opt.spp_primary < 0 || opt.spp_interior < -1)
    throw std::invalid_argument(scene.source + ": sample counts must be >= 0 (spp_interior also -1: the scene's)");
  if (interior_spp(scene, opt) == 0 && params.any_geometry())
    for (const Shape& s : scene.shapes)
      if (s.is_heightfield())  // Tong et al. 2023: its boundary terms ride on the interior paths
        throw std::invalid_argument(scene.source + ": heightfield '" + s.id + "' needs spp_interior >= 1 (its estimator has no separate boundary term)");
}

// The boundary terms that are switched on, built for this call (kept for the summary).
struct BoundaryTerms {
  std::unique_ptr<PrimaryBoundary> primary;
  std::unique_ptr<IndirectBoundary> indirect;
  std::shared_ptr<const BoundaryGuide> guide;
  double guide_seconds = 0.0;
  std::string guide_origin;  // how the guide was filled
  std::string guide_reuse;   // what the cache did
};

std::vector<std::string> summarize(const Scene& scene, const DiffParams& params, int spp, const DiffOptions& opt,
                                   const PrimaryBoundary* primary, const IndirectBoundary* indirect, const BoundaryTerms* terms) {
  std::vector<std::string> s;
  s.push_back(spp > 0 ? "interior term: " + std::to_string(spp) + " paths per pixel, material-form replay"
                      : std::string("interior term: off (spp_interior 0)"));
  if (!params.any_geometry()) {
    s.push_back("boundary terms: skipped, no differentiable geometry (nothing can change visibility)");
    return s;
  }
  if (opt.spp_primary == 0)
    s.push_back("primary visibility: switched off (spp_primary = 0): silhouettes seen directly are missing");
  else if (!primary || primary->empty())
    s.push_back("primary visibility: skipped, no silhouette of a differentiable shape is in front of the camera");
  else
    s.push_back("primary visibility: " + std::to_string(opt.spp_primary) + " samples per pixel over " +
                std::to_string(primary->curve_count()) + " silhouette curves" +
                (primary->skipped_edges() ? " (" + std::to_string(primary->skipped_edges()) + " edges crossing the near plane skipped)" : ""));
  if (opt.spp_boundary == 0)
    s.push_back("indirect boundary: switched off (spp_boundary = 0): derivatives of shadows and of silhouettes seen "
                "in reflections are missing");
  else if (!indirect || indirect->empty())
    s.push_back("indirect boundary: skipped, the differentiable shapes have no edge that can be a silhouette");
  else
    s.push_back("indirect boundary: " + std::to_string(opt.spp_boundary) + " samples per pixel over " +
                std::to_string(indirect->space().edge_count()) + " edges and " + std::to_string(indirect->space().sphere_count()) +
                " sphere surfaces (" + std::to_string(indirect->space().static_count()) +
                " of them static: they count where a moving surface ends the segment), " +
                (terms && terms->guide ? "guiding " + terms->guide->describe() + ", " + terms->guide_origin + ", built in " +
                                             std::to_string(terms->guide_seconds) + " s" + terms->guide_reuse + ", " +
                                             std::to_string(terms->guide->memory_bytes() / 1024) + " KiB, 10% uniform defensive mixture"
                                      : std::string("guiding none (uniform)")));
  return s;
}

// Boundary samples j = 0 .. n-1 in parallel blocks; fn(j, rng, inputs) per sample with the tape
// cleared. Streams are seeded from (seed, tag, j), disjoint from the interior term's pixel streams.
template <typename Fn>
void for_each_boundary_sample(uint64_t n, uint64_t tag, const DiffOptions& opt, Fn&& fn) {
  constexpr uint64_t kBlock = 1024;
  tbb::task_arena arena(opt.threads > 0 ? opt.threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<uint64_t>(0, (n + kBlock - 1) / kBlock, 1), [&](const tbb::blocked_range<uint64_t>& r) {
      PathInputs in;
      for (uint64_t blk = r.begin(); blk != r.end(); ++blk)
        for (uint64_t j = blk * kBlock; j < std::min(n, (blk + 1) * kBlock); ++j) {
          Pcg32 rng = pixel_rng(mix_bits(opt.seed ^ tag), j);
          ad::Tape::current().clear();
          in.clear();
          fn(j, rng, in);
        }
    });
  });
}

constexpr uint64_t kPrimaryTag = 0x7072696d61727921ULL, kIndirectTag = 0x696e646972656374ULL;

uint64_t samples_for(const Scene& scene, int per_pixel) {
  return uint64_t(per_pixel) * uint64_t(scene.camera.width) * uint64_t(scene.camera.height);
}

// Tangent-weighted derivative of a tape variable.
double directional(const ad::Var& v, const PathInputs& in, const std::vector<double>& tangent, std::vector<double>& adj) {
  ad::Tape::current().backward(v.idx, 1.0, adj);
  double d = 0;
  for (const auto& [node, slot] : in.nodes) d += adj[node] * tangent[slot];
  return d;
}

void fill_stats(DiffStats* stats, std::chrono::steady_clock::time_point start, uint64_t paths, uint64_t rays, uint64_t invalid,
                std::vector<std::string> summary) {
  if (!stats) return;
  stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  stats->paths = paths;
  stats->rays = rays;
  stats->invalid_paths = invalid;
  stats->summary = std::move(summary);
}

// One camera path of pixel (x, y) replayed on a cleared tape (the same film sample as render()).
ad::V3<ad::Var> replay_camera_path(const Scene& scene, const DiffParams& params, int x, int y, Pcg32& rng, PathInputs& in,
                                   PathCounters& counters, int max_depth) {
  ad::Tape::current().clear();
  in.clear();
  const Vec2 film = Vec2(float(x), float(y)) + rng.next_2d();
  return interior_path_radiance(scene, params, scene.camera.generate_ray(film), rng, in, counters, max_depth);
}

// The heightfield estimator when the scene holds a heightfield and geometry is differentiable
// (it then replaces the interior and both boundary terms), else null.
std::unique_ptr<HeightfieldEstimator> heightfield_estimator(const Scene& scene, const DiffParams& params, const DiffOptions& opt) {
  if (!params.any_geometry()) return nullptr;
  for (const Shape& s : scene.shapes)
    if (s.is_heightfield())
      return std::make_unique<HeightfieldEstimator>(scene, params, opt.heightfield, effective_max_depth(scene, opt.max_depth));
  return nullptr;
}

std::vector<std::string> summarize_heightfield(const Scene& scene, int spp, const DiffOptions& opt, const HeightfieldEstimator& e,
                                               const HeightfieldCounters& c) {
  std::vector<std::string> s;
  const Shape& hf = scene.shapes[e.heightfield_shape()];
  s.push_back("heightfield estimator (Tong et al. 2023) for '" + hf.id + "' (" + std::to_string(hf.heightfield().nx) + " x " +
              std::to_string(hf.heightfield().ny) + " heights): " + std::to_string(spp) +
              " paths per pixel, theta reparameterised at the discontinuities of each azimuth slice; " +
              std::to_string(c.searches) + " peak searches visited " + std::to_string(c.search.nodes) + " mipmap nodes and " +
              std::to_string(c.search.cells) + " cells" +
              (!opt.heightfield.search.use_mipmap       ? " (brute force: no mipmap skipping)"
               : opt.heightfield.search.curvature_test ? " (curvature tests: " + std::to_string(c.search.curvature_hidden) + " nodes hidden, " +
                                                             std::to_string(c.search.curvature_rising) + " rising)"
                                                       : " (maximum test only)") +
              (opt.heightfield.theta_subrange_degrees > 0.0f
                   ? ", theta searched in sub-ranges of " + std::to_string(opt.heightfield.theta_subrange_degrees) + " degrees (App. C)"
                   : std::string()));
  s.push_back("primary visibility and indirect boundary terms: not needed (the heightfield estimator reparameterises them)");
  if (c.delta_light_samples)
    s.push_back("point/directional lights: " + std::to_string(c.delta_light_samples) +
                " shadow rays; their shadow edges are not differentiated (use area emitters for shadow derivatives)");
  if (c.other_shape_hits)
    s.push_back("warning: " + std::to_string(c.other_shape_hits) +
                " rays met shapes other than the heightfield and emitters, whose silhouettes are not split: derivatives may be "
                "biased where those shapes occlude");
  if (c.empty_ranges) s.push_back(std::to_string(c.empty_ranges) + " samples had an empty theta-range (value 0, counted)");
  return s;
}

// One camera sample of pixel (x, y) on a cleared tape: the heightfield estimator's, or the
// interior term's replay.
ad::V3<ad::Var> camera_path(const Scene& scene, const DiffParams& params, const HeightfieldEstimator* hfe,
                            tbb::enumerable_thread_specific<HeightfieldCounters>& hf_counters, int x, int y, Pcg32& rng,
                            PathInputs& in, PathCounters& counters, int max_depth) {
  if (!hfe) return replay_camera_path(scene, params, x, y, rng, in, counters, max_depth);
  ad::Tape::current().clear();
  in.clear();
  HeightfieldCounters& c = hf_counters.local();
  const uint64_t before = c.rays;
  const ad::V3<ad::Var> L = hfe->pixel(x, y, rng, in, c);
  counters.rays += c.rays - before;
  return L;
}

void finish_heightfield(DiffStats* stats, std::chrono::steady_clock::time_point start, uint64_t paths, const std::atomic<uint64_t>& rays,
                        const std::atomic<uint64_t>& invalid, const Scene& scene, int spp, const DiffOptions& opt,
                        const HeightfieldEstimator& e, tbb::enumerable_thread_specific<HeightfieldCounters>& hf_counters) {
  HeightfieldCounters total;
  for (const auto& c : hf_counters) total.add(c);
  fill_stats(stats, start, paths, rays, invalid, summarize_heightfield(scene, spp, opt, e, total));
}

bool finite_adjoints(const std::vector<double>& adj, const PathInputs& in) {
  for (const auto& [node, slot] : in.nodes)
    if (!std::isfinite(adj[node])) return false;
  return true;
}


// Point j of a call's n points of the boundary sample space [0,1)^3, as boundary_sampler says:
// stratified (core/math/sequence.h) or independent.
class BoundaryPoints {
 public:
  BoundaryPoints(const DiffOptions& opt, uint64_t n, uint64_t tag)
      : m_stratify(opt.boundary_sampler == "stratified"), m_sequence(n, mix_bits(opt.seed ^ tag)) {}
  Vec3d operator()(uint64_t j, Pcg32& rng) const {
    return m_stratify ? m_sequence.point(j, rng) : Vec3d(rng.next_double(), rng.next_double(), rng.next_double());
  }

 private:
  bool m_stratify;
  StratifiedSequence3 m_sequence;
};

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
void build_guide(const Scene& scene, const IndirectBoundary& ib, const DiffOptions& opt, int max_depth, BoundaryTerms& terms) {
  auto integrand = [&](const Vec3& u) { return ib.guide_value(u); };
  const std::array<int, 3> res = grid_cells(opt);
  if (opt.guiding == "grid" && !opt.projective) {
    terms.guide = std::make_shared<BoundaryGrid>(res, opt.guiding_spp, opt.seed, opt.threads, integrand);
    terms.guide_origin = std::to_string(opt.guiding_spp) + " random points per cell";
    return;
  }
  const Projector projector(scene, ib.space());
  SeedStats st;
  const uint64_t paths = uint64_t(seeds_per_pixel(opt)) * uint64_t(scene.camera.width) * uint64_t(scene.camera.height);
  const std::vector<Projection> seeds =
      projected_seeds(scene, projector, paths, parse_seed_segments(opt.project_seed, scene.source), max_depth, opt.seed, opt.threads, &st);
  std::vector<Vec3> points(seeds.size());
  for (size_t i = 0; i < seeds.size(); ++i) points[i] = seeds[i].u;
  terms.guide_origin = std::to_string(st.paths) + " seed paths (" + opt.project_seed + " segments): " + std::to_string(st.segments) +
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
  if (opt.octree_training > 0) training_points(scene, opt, integrand, *projective_grid, arena, trained, trained_values, terms.guide_origin);
  auto octree = std::make_shared<BoundaryOctree>(points, opt.octree, opt.seed, opt.threads, integrand, values, trained, trained_values);
  std::shared_ptr<const BoundaryGuide> guide = octree;
  if (opt.octree_grid_mix > 0.0f) guide = std::make_shared<GuideMixture>(octree, grid, opt.octree_grid_mix);
  terms.guide = with_directions(guide);
}

// The moving geometry's values and bounding-box diagonal (what decides whether a guide is stale).
std::vector<float> moving_geometry(const Scene& scene, const DiffParams& params, float& extent) {
  std::vector<float> g;
  Vec3 lo(kInfinity), hi(-kInfinity);
  for (int si : params.moving_shapes()) {
    const Shape& sh = scene.shapes[si];
    if (sh.is_mesh()) {
      g.insert(g.end(), sh.mesh().positions.begin(), sh.mesh().positions.end());
    } else if (sh.is_heightfield()) {
      continue;  // never guided: the heightfield estimator has no boundary sample space
    } else {
      const Sphere& sp = sh.sphere();
      g.insert(g.end(), {sp.center.x, sp.center.y, sp.center.z, sp.radius});
    }
  }
  for (size_t i = 0; i + 2 < g.size(); i += 3) {
    lo = glm::min(lo, Vec3(g[i], g[i + 1], g[i + 2]));
    hi = glm::max(hi, Vec3(g[i], g[i + 1], g[i + 2]));
  }
  extent = g.size() >= 3 ? glm::length(hi - lo) : 0.0f;
  return g;
}

// Builds the guide, or reuses the cached one (DiffOptions::guide_cache, GuideCache's rules).
void guide_for_call(const Scene& scene, const DiffParams& params, const IndirectBoundary& ib, const DiffOptions& opt,
                    BoundaryTerms& terms) {
  GuideCache* cache = opt.guide_refresh > 0 ? opt.guide_cache : nullptr;
  const std::string key = opt.guiding + "|" + (opt.projective ? "p" : "u") + "|" + opt.project_seed + "|" +
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
      terms.guide_origin = cache->origin;
      terms.guide_seconds = 0.0;
      cache->uses++;
      cache->reuses++;
      terms.guide_reuse = " (reused: call " + std::to_string(cache->uses) + " of " + std::to_string(opt.guide_refresh) +
                          " since it was built in " + std::to_string(cache->build_seconds) + " s)";
      return;
    }
  }
  lock.unlock();
  const auto t0 = std::chrono::steady_clock::now();
  build_guide(scene, ib, opt, effective_max_depth(scene, opt.max_depth), terms);
  terms.guide_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  lock.lock();
  if (cache) {
    *cache = GuideCache{terms.guide, key, terms.guide_origin, geometry, extent, 1, terms.guide_seconds, cache->builds + 1, cache->reuses};
    terms.guide_reuse = " (kept for up to " + std::to_string(opt.guide_refresh) + " calls)";
  }
}

// Runs every enabled boundary term. visit(inputs, splats, velocities) is called once per sample:
// the sample adds splat.value * d(velocities[splat.velocity]) to splat.pixel, values already
// divided by the term's sample count.
template <typename Visit>
BoundaryTerms run_boundary_terms(const Scene& scene, const DiffParams& params, const DiffOptions& opt,
                                 std::atomic<uint64_t>& rays, Visit&& visit) {
  BoundaryTerms terms;
  if (!params.any_geometry()) return terms;
  if (opt.spp_primary > 0) {
    terms.primary = std::make_unique<PrimaryBoundary>(scene, params, effective_max_depth(scene, opt.max_depth));
    const uint64_t n = samples_for(scene, opt.spp_primary);
    if (!terms.primary->empty())
      for_each_boundary_sample(n, kPrimaryTag, opt, [&](uint64_t, Pcg32& rng, PathInputs& in) {
        int pixel;
        Spectrum dL;
        ad::Var vn;
        uint64_t r = 0;
        const bool ok = terms.primary->sample(rng, in, pixel, dL, vn, r);
        rays += r;
        if (!ok || vn.is_constant()) return;
        visit(in, std::vector<IndirectBoundary::Splat>{{pixel, dL / float(n), 0}}, std::vector<ad::Var>{vn});
      });
  }
  if (opt.spp_boundary > 0) {
    terms.indirect = std::make_unique<IndirectBoundary>(scene, params, effective_max_depth(scene, opt.max_depth));
    const uint64_t n = samples_for(scene, opt.spp_boundary);
    if (!terms.indirect->empty() && opt.guiding != "none") guide_for_call(scene, params, *terms.indirect, opt, terms);
    const BoundaryPoints point(opt, n, kIndirectTag);
    if (!terms.indirect->empty())
      for_each_boundary_sample(n, kIndirectTag, opt, [&](uint64_t j, Pcg32& rng, PathInputs& in) {
        std::vector<IndirectBoundary::Splat> splats;
        std::vector<ad::Var> vel;
        uint64_t r = 0;
        const Vec3d u01 = point(j, rng);
        if (terms.guide) {
          float pdf_u;
          const Vec3 u = terms.guide->sample(u01, &pdf_u);
          terms.indirect->sample_at(u, pdf_u, terms.guide->pdf_first(u.x), rng, in, splats, vel, r);
        } else {
          terms.indirect->sample_at(glm::min(Vec3(u01), Vec3(0x1.fffffep-1f)), 1.0f, 1.0f, rng, in, splats, vel, r);
        }
        rays += r;
        if (splats.empty()) return;
        for (auto& sp : splats) sp.value /= float(n);
        visit(in, splats, vel);
      });
  }
  return terms;
}

}  // namespace

std::shared_ptr<const BoundaryGuide> build_boundary_guide(const Scene& scene, const IndirectBoundary& indirect, const DiffOptions& opt,
                                                          std::string* origin) {
  if (opt.guiding != "grid" && opt.guiding != "octree")
    throw std::invalid_argument(scene.source + ": build_boundary_guide needs guiding 'grid' or 'octree' (got '" + opt.guiding + "')");
  BoundaryTerms terms;
  build_guide(scene, indirect, opt, effective_max_depth(scene, opt.max_depth), terms);
  if (origin) *origin = terms.guide_origin;
  return terms.guide;
}

Image render_forward(const Scene& scene, const DiffParams& params, const std::vector<double>& tangent,
                     const DiffOptions& opt, DiffStats* stats) {
  validate(scene, params, opt);
  if (tangent.size() != params.slot_count())
    throw std::invalid_argument(scene.source + ": tangent has " + std::to_string(tangent.size()) + " values, expected " +
                                std::to_string(params.slot_count()));
  const auto start = std::chrono::steady_clock::now();
  const auto lock = scene.render_lock();
  const int max_depth = effective_max_depth(scene, opt.max_depth);
  const int W = scene.camera.width, H = scene.camera.height;
  const int spp = interior_spp(scene, opt);
  Image img{W, H, std::vector<float>(size_t(W) * H * 3, 0.0f)};
  std::atomic<uint64_t> rays{0}, invalid{0};
  const std::unique_ptr<HeightfieldEstimator> hfe = heightfield_estimator(scene, params, opt);
  tbb::enumerable_thread_specific<HeightfieldCounters> hf_counters;

  for_each_pixel(scene, opt, [&](int x, int y) {
    Pcg32 rng = pixel_rng(opt.seed, uint64_t(y) * W + x);
    PathInputs in;
    std::vector<double> adj;
    PathCounters counters;
    double sum[3] = {0, 0, 0};
    uint64_t bad = 0;
    for (int s = 0; s < spp; ++s) {
      const ad::V3<ad::Var> L = camera_path(scene, params, hfe.get(), hf_counters, x, y, rng, in, counters, max_depth);
      double d[3] = {0, 0, 0};
      bool ok = std::isfinite(L.x.v) && std::isfinite(L.y.v) && std::isfinite(L.z.v);
      for (int c = 0; c < 3 && ok; ++c) {
        const ad::Var& out = c == 0 ? L.x : (c == 1 ? L.y : L.z);
        if (out.is_constant()) continue;
        ad::Tape::current().backward(out.idx, 1.0, adj);
        ok = finite_adjoints(adj, in);
        for (const auto& [node, slot] : in.nodes) d[c] += adj[node] * tangent[slot];
      }
      if (!ok || !std::isfinite(d[0] + d[1] + d[2])) {
        ++bad;
        continue;
      }
      for (int c = 0; c < 3; ++c) sum[c] += d[c];
    }
    float* px = &img.rgb[3 * (size_t(y) * W + x)];
    for (int c = 0; c < 3; ++c) px[c] = spp > 0 ? float(sum[c] / spp) : 0.0f;
    rays += counters.rays;
    invalid += bad;
  });
  if (hfe) {
    ad::Tape::current().clear();
    finish_heightfield(stats, start, uint64_t(W) * H * spp, rays, invalid, scene, spp, opt, *hfe, hf_counters);
    return img;
  }
  // Boundary terms splat into per-thread images.
  ThreadSums images(size_t(W) * H * 3);
  const BoundaryTerms terms = run_boundary_terms(scene, params, opt, rays, [&](const PathInputs& in,
      const std::vector<IndirectBoundary::Splat>& splats, const std::vector<ad::Var>& vel) {
    std::vector<double> adj, d(vel.size(), 0.0);
    for (size_t i = 0; i < vel.size(); ++i) d[i] = vel[i].is_constant() ? 0.0 : directional(vel[i], in, tangent, adj);
    std::vector<double>& im = images.local();
    for (const auto& sp : splats) {
      if (!std::isfinite(d[sp.velocity])) continue;
      for (int c = 0; c < 3; ++c) im[3 * size_t(sp.pixel) + c] += double(sp.value[c]) * d[sp.velocity];
    }
  });
  const std::vector<double> splatted = images.reduce();
  for (size_t i = 0; i < splatted.size(); ++i) img.rgb[i] += float(splatted[i]);
  ad::Tape::current().clear();
  fill_stats(stats, start, uint64_t(W) * H * spp, rays, invalid, summarize(scene, params, spp, opt, terms.primary.get(), terms.indirect.get(), &terms));
  return img;
}

std::vector<double> render_backward(const Scene& scene, const DiffParams& params, const Image& adjoint,
                                    const DiffOptions& opt, DiffStats* stats) {
  validate(scene, params, opt);
  const int W = scene.camera.width, H = scene.camera.height;
  if (adjoint.width != W || adjoint.height != H)
    throw std::invalid_argument(scene.source + ": adjoint image is " + std::to_string(adjoint.width) + "x" +
                                std::to_string(adjoint.height) + ", the film is " + std::to_string(W) + "x" + std::to_string(H));
  for (float a : adjoint.rgb)
    if (!std::isfinite(a)) throw std::invalid_argument(scene.source + ": the adjoint image has non-finite values");
  const auto start = std::chrono::steady_clock::now();
  const auto lock = scene.render_lock();
  const int max_depth = effective_max_depth(scene, opt.max_depth);
  const int spp = interior_spp(scene, opt);
  ThreadSums grads(params.slot_count());
  std::atomic<uint64_t> rays{0}, invalid{0};
  const std::unique_ptr<HeightfieldEstimator> hfe = heightfield_estimator(scene, params, opt);
  tbb::enumerable_thread_specific<HeightfieldCounters> hf_counters;

  for_each_pixel(scene, opt, [&](int x, int y) {
    Pcg32 rng = pixel_rng(opt.seed, uint64_t(y) * W + x);
    const float* a = &adjoint.rgb[3 * (size_t(y) * W + x)];
    std::vector<double>& g = grads.local();
    PathInputs in;
    std::vector<double> adj;
    PathCounters counters;
    uint64_t bad = 0;
    for (int s = 0; s < spp; ++s) {
      const ad::V3<ad::Var> L = camera_path(scene, params, hfe.get(), hf_counters, x, y, rng, in, counters, max_depth);
      if (!(std::isfinite(L.x.v) && std::isfinite(L.y.v) && std::isfinite(L.z.v))) {
        ++bad;
        continue;
      }
      // One sweep for the adjoint-weighted sum over channels.
      const ad::Var out = L.x * ad::Var(a[0]) + L.y * ad::Var(a[1]) + L.z * ad::Var(a[2]);
      if (out.is_constant()) continue;
      ad::Tape::current().backward(out.idx, 1.0 / spp, adj);
      if (!finite_adjoints(adj, in)) {
        ++bad;
        continue;
      }
      for (const auto& [node, slot] : in.nodes) g[slot] += adj[node];
    }
    rays += counters.rays;
    invalid += bad;
  });
  if (hfe) {
    ad::Tape::current().clear();
    finish_heightfield(stats, start, uint64_t(W) * H * spp, rays, invalid, scene, spp, opt, *hfe, hf_counters);
    return grads.reduce();
  }
  auto scatter = [&](const ad::Var& v, double weight, const PathInputs& in) {
    if (weight == 0.0 || v.is_constant()) return;
    std::vector<double> adj;
    ad::Tape::current().backward(v.idx, weight, adj);
    if (!finite_adjoints(adj, in)) return;
    std::vector<double>& g = grads.local();
    for (const auto& [node, slot] : in.nodes) g[slot] += adj[node];
  };
  auto adjoint_dot = [&](int pixel, const Spectrum& v) {
    const float* a = &adjoint.rgb[3 * size_t(pixel)];
    return double(a[0]) * v.x + double(a[1]) * v.y + double(a[2]) * v.z;
  };
  const BoundaryTerms terms = run_boundary_terms(scene, params, opt, rays, [&](const PathInputs& in,
      const std::vector<IndirectBoundary::Splat>& splats, const std::vector<ad::Var>& vel) {
    std::vector<double> w(vel.size(), 0.0);
    for (const auto& sp : splats) w[sp.velocity] += adjoint_dot(sp.pixel, sp.value);
    for (size_t i = 0; i < vel.size(); ++i) scatter(vel[i], w[i], in);
  });
  ad::Tape::current().clear();
  std::vector<double> total = grads.reduce();
  fill_stats(stats, start, uint64_t(W) * H * spp, rays, invalid, summarize(scene, params, spp, opt, terms.primary.get(), terms.indirect.get(), &terms));
  return total;
}

}  // namespace limn
