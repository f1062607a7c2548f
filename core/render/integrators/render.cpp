#include "core/render/integrators/render.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <atomic>
#include <chrono>
#include <mutex>
#include "core/render/integrators/path.h"

namespace limn {

Image render(const Scene& scene, const RenderOptions& options, RenderStats* stats) {
  const auto start = std::chrono::steady_clock::now();
  const auto lock = scene.render_lock();
  const int W = scene.camera.width, H = scene.camera.height;
  const int spp = options.spp > 0 ? options.spp : scene.spp;
  if (spp <= 0 || spp > kMaxSpp)
    throw std::invalid_argument(scene.source + ": spp must be in [1, " + std::to_string(kMaxSpp) + "] (got " + std::to_string(spp) + ")");
  if (options.threads < 0 || options.threads > kMaxThreads)
    throw std::invalid_argument(scene.source + ": threads must be in [0, " + std::to_string(kMaxThreads) + "] (0: all cores; got " +
                                std::to_string(options.threads) + ")");
  const uint64_t invalid_rays_before = scene.invalid_rays();
  const int max_depth = effective_max_depth(scene, options.max_depth);
  Image img{W, H, std::vector<float>(size_t(W) * H * 3, 0.0f)};

  constexpr int kTile = 16;
  const int tiles_x = (W + kTile - 1) / kTile, tiles_y = (H + kTile - 1) / kTile;
  const int tile_count = tiles_x * tiles_y;
  std::atomic<int> tiles_done{0};
  std::atomic<bool> cancelled{false};
  std::atomic<uint64_t> rays{0}, invalid{0};
  std::mutex progress_mutex;

  auto render_tile = [&](int tile) {
    if (cancelled.load(std::memory_order_relaxed)) return;
    const int x0 = (tile % tiles_x) * kTile, y0 = (tile / tiles_x) * kTile;
    PathCounters counters;
    uint64_t bad = 0;
    for (int y = y0; y < std::min(y0 + kTile, H); ++y)
      for (int x = x0; x < std::min(x0 + kTile, W); ++x) {
        // Double sums: a float's rounding grows as sqrt(spp) relative to the pixel and would reach
        // finite differences of high-spp references divided by a small eps.
        Pcg32 rng = pixel_rng(options.seed, uint64_t(y) * W + x);
        glm::dvec3 sum(0.0);
        for (int s = 0; s < spp; ++s) {
          const Vec2 film = scene.camera.sample_film(x, y, rng.next_2d());
          const Spectrum L = path_radiance(scene, scene.camera.generate_ray(film), rng, counters, PathLimits{max_depth, true});
          if (is_finite(L) && L.x >= 0.0f && L.y >= 0.0f && L.z >= 0.0f) sum += glm::dvec3(L);
          else ++bad;
        }
        float* px = &img.rgb[3 * (size_t(y) * W + x)];
        px[0] = float(sum.x / spp);
        px[1] = float(sum.y / spp);
        px[2] = float(sum.z / spp);
      }
    rays += counters.rays;
    invalid += bad;
    const int done = ++tiles_done;
    if (options.progress && progress_mutex.try_lock()) {
      std::lock_guard<std::mutex> lock(progress_mutex, std::adopt_lock);
      if (!options.progress(float(done) / tile_count)) cancelled = true;
    }
  };

  tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, tile_count, 1), [&](const tbb::blocked_range<int>& r) {
      for (int t = r.begin(); t != r.end(); ++t) render_tile(t);
    });
  });
  if (cancelled) throw RenderCancelled();
  if (options.progress) options.progress(1.0f);

  if (stats) {
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    stats->samples = uint64_t(W) * H * spp;
    stats->rays = rays;
    stats->invalid_samples = invalid;
    stats->invalid_rays = scene.invalid_rays() - invalid_rays_before;
  }
  return img;
}

}  // namespace limn
