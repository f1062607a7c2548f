// Primal rendering: tiles over TBB threads, one PCG stream per pixel (thread-count independent).
#pragma once
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <vector>
#include "core/render/scene.h"

namespace limn {

struct Image {
  int width = 0, height = 0;
  std::vector<float> rgb;  // 3 floats per pixel, rows top to bottom, linear RGB
};

// The most worker threads a call may ask for (0 asks for all cores).
inline constexpr int kMaxThreads = 1024;
// The most samples per pixel a call or a scene may ask for: 8x the largest count limn's own
// benches use (131072). A mistyped count (2^31 - 1) is refused instead of running for days.
inline constexpr int kMaxSpp = 1 << 20;

struct RenderOptions {
  int spp = 0;             // 0: the scene's sampler sample_count
  uint64_t seed = 0;
  int threads = 0;         // 0: all cores
  int max_depth = kSceneMaxDepth;  // path integrator: overrides the scene's max_depth (-1: unbounded)
  // Called now and then with the finished fraction; returning false cancels the render.
  std::function<bool(float)> progress;
};

struct RenderStats {
  double seconds = 0.0;
  uint64_t samples = 0;
  uint64_t rays = 0;
  uint64_t invalid_samples = 0;  // NaN/Inf/negative path contributions, counted and dropped
  uint64_t invalid_rays = 0;     // rays that could not be traced (Scene::invalid_rays), missed
};

struct RenderCancelled : std::runtime_error {
  RenderCancelled() : std::runtime_error("render cancelled") {}
};

Image render(const Scene& scene, const RenderOptions& options, RenderStats* stats = nullptr);

}  // namespace limn
