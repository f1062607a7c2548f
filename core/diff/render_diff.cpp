#include "core/diff/render_diff.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <atomic>
#include <chrono>
#include <mutex>
#include "core/diff/interior.h"

namespace limn {
namespace {

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

void validate(const Scene& scene, const DiffParams& params, const DiffOptions& opt) {
  if (params.empty()) throw std::invalid_argument(scene.source + ": no differentiable parameters (call set_differentiable first)");
  if (opt.spp_primary != 0 || opt.spp_boundary != 0)
    throw std::invalid_argument(scene.source + ": boundary terms (spp_primary, spp_boundary) are not implemented yet; pass 0");
}

std::vector<std::string> summarize(const Scene& scene, const DiffParams& params, int spp) {
  std::vector<std::string> s;
  s.push_back("interior term: " + std::to_string(spp) + " paths per pixel, material-form replay");
  if (params.any_geometry())
    s.push_back("boundary terms: NOT COMPUTED (not implemented yet): derivatives caused by moving silhouettes, "
                "shadow edges and reflected edges of the differentiable shapes are missing");
  else
    s.push_back("boundary terms: skipped, no differentiable geometry (nothing can change visibility)");
  return s;
}

bool finite_adjoints(const std::vector<double>& adj, const PathInputs& in) {
  for (const auto& [node, slot] : in.nodes)
    if (!std::isfinite(adj[node])) return false;
  return true;
}

}  // namespace

Image render_forward(const Scene& scene, const DiffParams& params, const std::vector<double>& tangent,
                     const DiffOptions& opt, DiffStats* stats) {
  validate(scene, params, opt);
  if (tangent.size() != params.slot_count())
    throw std::invalid_argument(scene.source + ": tangent has " + std::to_string(tangent.size()) + " values, expected " +
                                std::to_string(params.slot_count()));
  const auto start = std::chrono::steady_clock::now();
  const auto lock = scene.render_lock();
  const int W = scene.camera.width, H = scene.camera.height;
  const int spp = opt.spp_interior > 0 ? opt.spp_interior : scene.spp;
  Image img{W, H, std::vector<float>(size_t(W) * H * 3, 0.0f)};
  std::atomic<uint64_t> rays{0}, invalid{0};

  for_each_pixel(scene, opt, [&](int x, int y) {
    Pcg32 rng = pixel_rng(opt.seed, uint64_t(y) * W + x);
    PathInputs in;
    std::vector<double> adj;
    PathCounters counters;
    double sum[3] = {0, 0, 0};
    uint64_t bad = 0;
    for (int s = 0; s < spp; ++s) {
      ad::Tape::current().clear();
      in.clear();
      const Vec2 film = Vec2(float(x), float(y)) + rng.next_2d();
      const ad::V3<ad::Var> L = interior_path_radiance(scene, params, scene.camera.generate_ray(film), rng, in, counters);
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
    for (int c = 0; c < 3; ++c) px[c] = float(sum[c] / spp);
    rays += counters.rays;
    invalid += bad;
  });
  ad::Tape::current().clear();
  if (stats) {
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    stats->paths = uint64_t(W) * H * spp;
    stats->rays = rays;
    stats->invalid_paths = invalid;
    stats->summary = summarize(scene, params, spp);
  }
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
  const int spp = opt.spp_interior > 0 ? opt.spp_interior : scene.spp;
  tbb::enumerable_thread_specific<std::vector<double>> grads(std::vector<double>(params.slot_count(), 0.0));
  std::atomic<uint64_t> rays{0}, invalid{0};

  for_each_pixel(scene, opt, [&](int x, int y) {
    Pcg32 rng = pixel_rng(opt.seed, uint64_t(y) * W + x);
    const float* a = &adjoint.rgb[3 * (size_t(y) * W + x)];
    std::vector<double>& g = grads.local();
    PathInputs in;
    std::vector<double> adj;
    PathCounters counters;
    uint64_t bad = 0;
    for (int s = 0; s < spp; ++s) {
      ad::Tape::current().clear();
      in.clear();
      const Vec2 film = Vec2(float(x), float(y)) + rng.next_2d();
      const ad::V3<ad::Var> L = interior_path_radiance(scene, params, scene.camera.generate_ray(film), rng, in, counters);
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
  ad::Tape::current().clear();
  std::vector<double> total(params.slot_count(), 0.0);
  for (const auto& g : grads)
    for (size_t i = 0; i < total.size(); ++i) total[i] += g[i];
  if (stats) {
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    stats->paths = uint64_t(W) * H * spp;
    stats->rays = rays;
    stats->invalid_paths = invalid;
    stats->summary = summarize(scene, params, spp);
  }
  return total;
}

}  // namespace limn
