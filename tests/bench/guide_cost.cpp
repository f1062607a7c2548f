// Cost of the octree guide's set-up (issue 36): `limn_guide_cost scene.json param [--samples N]
// [--build K] [--threads T]`. Times IndirectBoundary::guide_value (the integrand every leaf's
// uniform points evaluate) at N uniform points of the boundary sample space on one thread, split
// by what the point gives (zero, non-zero, no boundary point), then builds the default octree
// guide K times (T threads) and prints its set-up time and description. For perf:
// `perf record -g ./build/cpp/limn_guide_cost scenes/curves/coil_reflection.json coil.control_points`.
#include <chrono>
#include <cstdio>
#include <ctime>
#include <string>
#include "core/diff/guide_builder.h"
#include "core/diff/render_diff.h"
#include "core/diff/terms/indirect.h"
#include "core/guiding/guide.h"
#include "core/io/scene_loader.h"
#include "core/math/rng.h"

using namespace limn;

namespace {
// CPU time of the calling thread (the machine is shared: wall time says little).
double thread_seconds() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s scene.json param [--samples N] [--build K] [--threads T]\n", argv[0]);
    return 2;
  }
  size_t samples = 200000;
  int builds = 1, threads = 0;
  for (int a = 3; a + 1 < argc; a += 2) {
    const std::string k = argv[a];
    if (k == "--samples") samples = size_t(std::stoull(argv[a + 1]));
    else if (k == "--build") builds = std::stoi(argv[a + 1]);
    else if (k == "--threads") threads = std::stoi(argv[a + 1]);
    else {
      std::fprintf(stderr, "unknown option %s\n", argv[a]);
      return 2;
    }
  }
  try {
    const auto scene = load_scene_file(argv[1]);
    const DiffParams params(*scene, {argv[2]});
    const IndirectBoundary ib(*scene, params, effective_max_depth(*scene, kSceneMaxDepth));
    using clock = std::chrono::steady_clock;
    if (samples > 0) {
      // Uniform points (most of them give no boundary point or a zero value), then points drawn
      // from the projective grid (where the octree's leaves, and so its uniform points, crowd).
      DiffOptions go;
      go.guiding = "grid";
      go.threads = threads;
      const auto grid = build_boundary_guide(*scene, ib, go);
      for (int pass = 0; pass < 2; ++pass) {
        Pcg32 rng(12345, 1);
        size_t nonzero = 0;
        double sum = 0.0;
        const double t0 = thread_seconds();
        for (size_t i = 0; i < samples; ++i) {
          const Vec3d r(rng.next_double(), rng.next_double(), rng.next_double());
          float pdf;
          const Vec3 u = pass == 0 ? glm::min(Vec3(r), Vec3(1.0f - 1e-7f)) : grid->sample(r, &pdf);
          const float f = ib.guide_value(u);
          if (f > 0.0f) ++nonzero, sum += f;
        }
        const double s = thread_seconds() - t0;
        std::printf("guide_value at %zu %s points: %.3f us CPU each, %zu non-zero, mean %.6g\n", samples,
                    pass == 0 ? "uniform" : "projective-grid", 1e6 * s / double(samples), nonzero, sum / double(samples));
      }
    }
    for (int b = 0; b < builds; ++b) {
      DiffOptions o;
      o.guiding = "octree";
      o.threads = threads;
      o.seed = uint64_t(1000 + b);
      std::string origin;
      const auto t0 = clock::now();
      const double c0 = std::clock();
      const auto guide = build_boundary_guide(*scene, ib, o, &origin);
      const double s = std::chrono::duration<double>(clock::now() - t0).count(), cpu = (std::clock() - c0) / CLOCKS_PER_SEC;
      std::printf("octree build %d: %.2f s wall, %.2f s CPU (all threads); %s; %s\n", b, s, cpu, origin.c_str(), guide->describe().c_str());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 1;
  }
  return 0;
}
