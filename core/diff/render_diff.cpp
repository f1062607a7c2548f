#include "core/diff/render_diff.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <atomic>
#include <chrono>
#include <mutex>
#include "core/diff/terms/interior.h"
#include "core/diff/terms/indirect.h"
#include "core/diff/terms/primary.h"

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

// The boundary terms that are switched on, built for this call (kept for the summary).
struct BoundaryTerms {
  std::unique_ptr<PrimaryBoundary> primary;
  std::unique_ptr<IndirectBoundary> indirect;
  CallGuide guide;
};

std::vector<std::string> summarize(const Scene& scene, const DiffParams& params, int spp, const DiffOptions& opt,
                                   const PrimaryBoundary* primary, const IndirectBoundary* indirect, const BoundaryTerms* terms) {
  std::vector<std::string> s;
  s.push_back(spp > 0 ? "interior term: " + std::to_string(spp) + " paths per pixel, material-form replay" +
                            (params.any_geometry() ? std::string(opt.shading_horizon ? ", with the smooth-shading horizon term"
                                                                                     : ", smooth-shading horizon term off (shading_horizon)")
                                                   : std::string())
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
                (primary->skipped_edges() ? " (" + std::to_string(primary->skipped_edges()) + " edges crossing the near plane skipped)" : "") +
                (primary->mirror_views() ? ", seen directly and through " + std::to_string(primary->mirror_views()) + " chains of planar mirror reflections" : ""));
  if (opt.spp_primary > 0 && primary)
    for (const std::string& note : primary->notes()) s.push_back("primary visibility: " + note);
  if (opt.spp_boundary == 0)
    s.push_back("indirect boundary: switched off (spp_boundary = 0): derivatives of shadows and of silhouettes seen "
                "in reflections are missing");
  else if (!indirect || indirect->empty())
    s.push_back("indirect boundary: skipped, the differentiable shapes have no edge that can be a silhouette");
  else {
    std::string segments;
    for (const auto& [name, count] : indirect->space().segment_counts())
      segments += (segments.empty() ? "" : " and ") + std::to_string(count) + " " + name;
    const CallGuide* g = terms && terms->guide.guide ? &terms->guide : nullptr;
    if (opt.boundary_parts != "both") segments += " (" + opt.boundary_parts + " part of Eq. 4 only: boundary_parts)";
    s.push_back("indirect boundary: " + std::to_string(opt.spp_boundary) + " samples per pixel over " + segments + " (" +
                std::to_string(indirect->space().static_count()) + " of them static: they count where a moving surface ends the segment), " +
                (g ? std::string(opt.guiding_auto ? "guiding auto (" + std::to_string(opt.spp_boundary) + " samples per pixel: " +
                                                        (opt.guiding == "octree" ? "the octree" : "the projective grid") + "): " : "") +
                         "guiding " + g->guide->describe() + ", " + g->origin + ", built in " + std::to_string(g->seconds) + " s" + g->reuse +
                         ", " + std::to_string(g->guide->memory_bytes() / 1024) + " KiB, 10% uniform defensive mixture"
                   : std::string(opt.guiding_auto ? "guiding auto: none (uniform), as every boundary segment ends at a point or "
                                                    "directional light, which fixes its direction"
                                                  : "guiding none (uniform)")));
    for (const std::string& id : indirect->space().left_out())
      s.push_back("indirect boundary: static shape '" + id + "' left out: its kind has no boundary segments");
    if (indirect->refraction_stacks())
      s.push_back("indirect boundary: camera connections also through " + std::to_string(indirect->refraction_stacks()) +
                  " stacks of parallel flat glass interfaces");
    if (indirect->mirror_chains())
      s.push_back("indirect boundary: camera connections also through " + std::to_string(indirect->mirror_chains()) +
                  " chains of planar mirror reflections");
  }
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

constexpr uint64_t kPrimaryTag = 0x7072696d61727921ULL, kIndirectTag = 0x696e646972656374ULL,
                   kHeightfieldEdgeTag = 0x6866656467657321ULL;

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
                                   PathCounters& counters, int max_depth, bool horizon) {
  ad::Tape::current().clear();
  in.clear();
  const Vec2 film = scene.camera.sample_film(x, y, rng.next_2d());
  return interior_path_radiance(scene, params, scene.camera.generate_ray(film), rng, in, counters, max_depth, horizon);
}

// One camera sample of pixel (x, y) on a cleared tape: the heightfield estimator's, or the
// interior term's replay.
ad::V3<ad::Var> camera_path(const Scene& scene, const DiffParams& params, const HeightfieldEstimator* hfe,
                            tbb::enumerable_thread_specific<HeightfieldCounters>& hf_counters, int x, int y, Pcg32& rng,
                            PathInputs& in, PathCounters& counters, int max_depth, bool horizon) {
  if (!hfe) return replay_camera_path(scene, params, x, y, rng, in, counters, max_depth, horizon);
  ad::Tape::current().clear();
  in.clear();
  HeightfieldCounters& c = hf_counters.local();
  const uint64_t before = c.rays;
  const ad::V3<ad::Var> L = hfe->pixel(x, y, rng, in, c);
  counters.rays += c.rays - before;
  return L;
}

// Point lights' shadow edges cast by heightfields: calls visit(in, splats, velocities, n) for each
// of the call's n edge samples that reached the film (forward splats, backward scatters).
template <typename Visit>
void for_each_heightfield_edge(const Scene& scene, const DiffOptions& opt, int spp, const HeightfieldEstimator& e,
                               tbb::enumerable_thread_specific<HeightfieldCounters>& hf_counters, std::atomic<uint64_t>& rays, Visit visit) {
  const uint64_t n = samples_for(scene, opt.spp_boundary > 0 ? opt.spp_boundary : spp);
  for_each_boundary_sample(n, kHeightfieldEdgeTag, opt, [&](uint64_t, Pcg32& rng, PathInputs& in) {
    std::vector<HeightfieldSplat> splats;
    std::vector<ad::Var> vel;
    HeightfieldCounters& c = hf_counters.local();
    const uint64_t before = c.rays;
    const bool ok = e.delta_edge_sample(rng, in, splats, vel, c);
    rays += c.rays - before;
    if (ok) visit(in, splats, vel, n);
  });
}

void finish_heightfield(DiffStats* stats, std::chrono::steady_clock::time_point start, uint64_t paths, const std::atomic<uint64_t>& rays,
                        const std::atomic<uint64_t>& invalid, const Scene& scene, int spp, const DiffOptions& opt,
                        const HeightfieldEstimator& e, tbb::enumerable_thread_specific<HeightfieldCounters>& hf_counters) {
  HeightfieldCounters total;
  for (const auto& c : hf_counters) total.add(c);
  fill_stats(stats, start, paths, rays, invalid, e.summary(spp, total));
}

bool finite_adjoints(const std::vector<double>& adj, const PathInputs& in) {
  for (const auto& [node, slot] : in.nodes)
    if (!std::isfinite(adj[node])) return false;
  return true;
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
        glm::dvec2 film;
        Spectrum dL;
        ad::Var vn;
        uint64_t r = 0;
        const bool ok = terms.primary->sample(rng, in, film, dL, vn, r);
        rays += r;
        if (!ok || vn.is_constant()) return;
        std::vector<IndirectBoundary::Splat> splats;
        scene.camera.splat(film.x, film.y, [&](int pixel, float w) { splats.push_back({pixel, dL * w / float(n), 0}); });
        if (!splats.empty()) visit(in, splats, std::vector<ad::Var>{vn});
      });
  }
  if (opt.spp_boundary > 0) {
    terms.indirect = std::make_unique<IndirectBoundary>(scene, params, effective_max_depth(scene, opt.max_depth), opt.boundary_parts != "interior",
                                                        opt.boundary_parts != "perimeter");
    const uint64_t n = samples_for(scene, opt.spp_boundary);
    if (!terms.indirect->empty() && opt.guiding != "none") terms.guide = guide_for_call(scene, params, *terms.indirect, opt);
    const BoundaryPoints point(opt, n, kIndirectTag);
    if (!terms.indirect->empty())
      for_each_boundary_sample(n, kIndirectTag, opt, [&](uint64_t j, Pcg32& rng, PathInputs& in) {
        std::vector<IndirectBoundary::Splat> splats;
        std::vector<ad::Var> vel;
        uint64_t r = 0;
        const Vec3d u01 = point(j, rng);
        if (const BoundaryGuide* guide = terms.guide.guide.get()) {
          float pdf_u;
          const Vec3 u = guide->sample(u01, &pdf_u);
          terms.indirect->sample_at(u, pdf_u, guide->pdf_first(u.x), rng, in, splats, vel, r);
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

namespace {

Image forward(const Scene& scene, const DiffParams& params, const std::vector<double>& tangent, const DiffOptions& options,
              DiffStats* stats) {
  validate_diff_options(scene, params, options);
  const DiffOptions opt = resolve_options(scene, options);
  if (tangent.size() != params.slot_count())
    throw std::invalid_argument(scene.source + ": tangent has " + std::to_string(tangent.size()) + " values, expected " +
                                std::to_string(params.slot_count()));
  const auto start = std::chrono::steady_clock::now();
  const auto lock = scene.render_lock();
  const int max_depth = effective_max_depth(scene, opt.max_depth);
  const int W = scene.camera.width, H = scene.camera.height;
  const int spp = opt.spp_interior;
  Image img{W, H, std::vector<float>(size_t(W) * H * 3, 0.0f)};
  std::atomic<uint64_t> rays{0}, invalid{0};
  const std::unique_ptr<HeightfieldEstimator> hfe =
      heightfield_estimator(scene, params, opt.heightfield, effective_max_depth(scene, opt.max_depth), spp);
  tbb::enumerable_thread_specific<HeightfieldCounters> hf_counters;

  for_each_pixel(scene, opt, [&](int x, int y) {
    Pcg32 rng = pixel_rng(opt.seed, uint64_t(y) * W + x);
    PathInputs in;
    std::vector<double> adj;
    PathCounters counters;
    double sum[3] = {0, 0, 0};
    uint64_t bad = 0;
    for (int s = 0; s < spp; ++s) {
      const ad::V3<ad::Var> L = camera_path(scene, params, hfe.get(), hf_counters, x, y, rng, in, counters, max_depth, opt.shading_horizon && params.any_geometry());
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
    if (hfe->has_delta_edges()) {  // point lights' shadow edges cast by heightfields, splatted
      ThreadSums images(size_t(W) * H * 3);
      for_each_heightfield_edge(scene, opt, spp, *hfe, hf_counters, rays, [&](PathInputs& in, const std::vector<HeightfieldSplat>& splats,
                                                                             const std::vector<ad::Var>& vel, uint64_t n) {
        std::vector<double> adj, d(vel.size(), 0.0);
        for (size_t i = 0; i < vel.size(); ++i) d[i] = vel[i].is_constant() ? 0.0 : directional(vel[i], in, tangent, adj);
        std::vector<double>& im = images.local();
        for (const auto& sp : splats) {
          if (!std::isfinite(d[sp.velocity])) continue;
          for (int ch = 0; ch < 3; ++ch) im[3 * size_t(sp.pixel) + ch] += double(sp.value[ch]) * d[sp.velocity] / double(n);
        }
      });
      const std::vector<double> splatted = images.reduce();
      for (size_t i = 0; i < splatted.size(); ++i) img.rgb[i] += float(splatted[i]);
    }
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

std::vector<double> backward(const Scene& scene, const DiffParams& params, const Image& adjoint, const DiffOptions& options,
                             DiffStats* stats) {
  validate_diff_options(scene, params, options);
  const DiffOptions opt = resolve_options(scene, options);
  const int W = scene.camera.width, H = scene.camera.height;
  if (adjoint.width != W || adjoint.height != H)
    throw std::invalid_argument(scene.source + ": adjoint image is " + std::to_string(adjoint.width) + "x" +
                                std::to_string(adjoint.height) + ", the film is " + std::to_string(W) + "x" + std::to_string(H));
  for (float a : adjoint.rgb)
    if (!std::isfinite(a)) throw std::invalid_argument(scene.source + ": the adjoint image has non-finite values");
  const auto start = std::chrono::steady_clock::now();
  const auto lock = scene.render_lock();
  const int max_depth = effective_max_depth(scene, opt.max_depth);
  const int spp = opt.spp_interior;
  ThreadSums grads(params.slot_count());
  std::atomic<uint64_t> rays{0}, invalid{0};
  const std::unique_ptr<HeightfieldEstimator> hfe =
      heightfield_estimator(scene, params, opt.heightfield, effective_max_depth(scene, opt.max_depth), spp);
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
      const ad::V3<ad::Var> L = camera_path(scene, params, hfe.get(), hf_counters, x, y, rng, in, counters, max_depth, opt.shading_horizon && params.any_geometry());
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
    if (hfe->has_delta_edges()) {  // point lights' shadow edges cast by heightfields, splatted
      for_each_heightfield_edge(scene, opt, spp, *hfe, hf_counters, rays, [&](PathInputs& in, const std::vector<HeightfieldSplat>& splats,
                                                                             const std::vector<ad::Var>& vel, uint64_t n) {
        std::vector<double> w(vel.size(), 0.0);
        for (const auto& sp : splats) {
          const float* a = &adjoint.rgb[3 * size_t(sp.pixel)];
          w[sp.velocity] += (double(a[0]) * sp.value.x + double(a[1]) * sp.value.y + double(a[2]) * sp.value.z) / double(n);
        }
        for (size_t i = 0; i < vel.size(); ++i) {
          if (w[i] == 0.0 || vel[i].is_constant()) continue;
          std::vector<double> adj;
          ad::Tape::current().backward(vel[i].idx, w[i], adj);
          if (!finite_adjoints(adj, in)) continue;
          std::vector<double>& g = grads.local();
          for (const auto& [node, slot] : in.nodes) g[slot] += adj[node];
        }
      });
    }
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

std::string format_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

// The largest |value| of each parameter's slots, e.g. "'box.vertex_positions' up to 1e+38".
std::string largest_per_parameter(const DiffParams& params, const std::vector<double>& values) {
  std::string out;
  for (const DiffParam& p : params.params()) {
    double m = 0.0;
    for (size_t i = 0; i < p.size; ++i) m = std::max(m, std::abs(values[p.offset + i]));
    out += (out.empty() ? "'" : ", '") + p.name + "' up to " + format_number(m);
  }
  return out;
}

void note_invalid_rays(DiffStats* stats, uint64_t n) {
  if (stats && n > 0)
    stats->summary.push_back("warning: " + std::to_string(n) +
                             " rays could not be traced (non-finite, or coordinates beyond 1.8e18) and missed");
}

}  // namespace

// A finite input gives a finite output or an error (docs/scene-format.md, "Non-finite values"):
// samples that are not finite are dropped inside the loops; a sum that overflows is refused here.
Image render_forward(const Scene& scene, const DiffParams& params, const std::vector<double>& tangent, const DiffOptions& options,
                     DiffStats* stats) {
  for (double t : tangent)
    if (!std::isfinite(t)) throw std::invalid_argument(scene.source + ": the tangent has non-finite values");
  const uint64_t invalid_rays = scene.invalid_rays();
  Image img = forward(scene, params, tangent, options, stats);
  size_t bad = 0;
  for (float v : img.rgb) bad += !std::isfinite(v);
  if (bad)
    throw std::invalid_argument(scene.source + ": the derivative image overflowed in " + std::to_string(bad) +
                                " values; the tangent reaches " + largest_per_parameter(params, tangent) + ": scale it down");
  note_invalid_rays(stats, scene.invalid_rays() - invalid_rays);
  return img;
}

std::vector<double> render_backward(const Scene& scene, const DiffParams& params, const Image& adjoint, const DiffOptions& options,
                                    DiffStats* stats) {
  const uint64_t invalid_rays = scene.invalid_rays();
  std::vector<double> grad = backward(scene, params, adjoint, options, stats);
  float largest = 0.0f;
  for (float a : adjoint.rgb) largest = std::max(largest, std::abs(a));
  for (const DiffParam& p : params.params())
    for (size_t i = 0; i < p.size; ++i)
      if (!std::isfinite(float(grad[p.offset + i])))  // float: what reaches Python
        throw std::invalid_argument(scene.source + ": the gradient of '" + p.name + "' overflowed (entry " + std::to_string(i) +
                                    "); the adjoint reaches " + format_number(largest) + ": scale it down");
  note_invalid_rays(stats, scene.invalid_rays() - invalid_rays);
  return grad;
}

}  // namespace limn
