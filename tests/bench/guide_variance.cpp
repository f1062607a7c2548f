// Relative variance of the indirect boundary estimate under each projective guide, rare tails
// included: `limn_guide_variance scene.json param [--seeds K] [--qspp N]`.
//
// A render of a few million samples rarely meets a guide's worst region (an edge's specular peak
// that no projection reached), so render errors over a few runs hide it. Here the second moment
// E_p[(f/p)^2] = E_q[f^2 / (p q)] of every guide p is estimated from N samples per pixel of one
// wide proposal q (four default octree guides from other seeds, mixed), which covers what any one
// guide misses; q's own relative variance is printed as a check. The integrand f is the guides'
// (IndirectBoundary::guide_value, without the tangent's velocity). Markdown on stdout.
#include <cmath>
#include <cstdio>
#include <string>
#include <tbb/parallel_for.h>
#include "core/diff/indirect.h"
#include "core/diff/render_diff.h"
#include "core/guiding/mixture.h"
#include "core/io/scene_loader.h"
#include "core/math/rng.h"

using namespace limn;

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s scene.json param [--seeds K] [--qspp N]\n", argv[0]);
    return 2;
  }
  int seeds = 4, qspp = 2048;
  for (int a = 3; a + 1 < argc; a += 2) {
    const std::string k = argv[a];
    if (k == "--seeds") seeds = std::stoi(argv[a + 1]);
    else if (k == "--qspp") qspp = std::stoi(argv[a + 1]);
    else {
      std::fprintf(stderr, "unknown option %s\n", argv[a]);
      return 2;
    }
  }
  try {
    const auto scene = load_scene_file(argv[1]);
    const DiffParams params(*scene, {argv[2]});
    const IndirectBoundary ib(*scene, params, effective_max_depth(*scene, kSceneMaxDepth));
    DiffOptions base;
    base.spp_boundary = 1024;  // the grid's seed paths as at the bench's 1024-spp rows
    auto options = [&](const std::string& guiding, float direction_mix, uint64_t seed) {
      DiffOptions o = base;
      o.guiding = guiding;
      o.direction_mix = direction_mix;
      o.seed = seed;
      return o;
    };
    std::shared_ptr<const BoundaryGuide> q = std::make_shared<GuideMixture>(
        std::make_shared<GuideMixture>(build_boundary_guide(*scene, ib, options("octree", kDirectionMix, 100001)),
                                       build_boundary_guide(*scene, ib, options("octree", kDirectionMix, 100002)), 0.5f),
        std::make_shared<GuideMixture>(build_boundary_guide(*scene, ib, options("octree", kDirectionMix, 100003)),
                                       build_boundary_guide(*scene, ib, options("octree", kDirectionMix, 100004)), 0.5f),
        0.5f);
    const size_t M = size_t(qspp) * scene->camera.width * scene->camera.height;
    std::vector<Vec3> u(M);
    std::vector<double> fq(M, 0.0);  // f / q, 0 where f or q is not usable
    tbb::parallel_for(size_t(0), M, [&](size_t i) {
      Pcg32 rng = pixel_rng(mix_bits(424242), i);
      float pdf;
      u[i] = q->sample(Vec3d(rng.next_double(), rng.next_float(), rng.next_float()), &pdf);
      const float f = ib.guide_value(u[i]);
      if (pdf > 0.0f && std::isfinite(f) && f > 0.0f) fq[i] = double(f) / pdf;
    });
    double F = 0.0, s2 = 0.0;
    for (double w : fq) {
      F += w / double(M);
      s2 += w * w / double(M);
    }
    std::printf("%s, `%s`: integral %.4g from %zu samples of the wide proposal (its own relative variance %.1f)\n\n", scene->source.c_str(),
                argv[2], F, M, s2 / (F * F) - 1.0);
    std::printf("| guide | direction histogram | relative variance per guide seed | mean |\n|---|---|---|---|\n");
    for (const std::string guiding : {"grid", "octree"})
      for (const float mix : {0.0f, kDirectionMix}) {
        std::string cells;
        double sum = 0.0;
        for (int t = 0; t < seeds; ++t) {
          const auto p = build_boundary_guide(*scene, ib, options(guiding, mix, 7 + 1000 * uint64_t(t)));
          std::vector<double> part(M);
          tbb::parallel_for(size_t(0), M, [&](size_t i) {
            const float pu = p->pdf(u[i]);
            part[i] = pu > 0.0f ? fq[i] * fq[i] * (q->pdf(u[i]) / pu) : 0.0;  // f^2 / (p q) = (f/q)^2 q / p
          });
          double m2 = 0.0;
          for (double v : part) m2 += v / double(M);
          const double rv = m2 / (F * F) - 1.0;
          sum += rv / seeds;
          cells += (t ? " " : "") + std::to_string(int(std::lround(rv)));
        }
        std::printf("| %s | %s | %s | %.0f |\n", guiding == "grid" ? "projective grid" : "octree",
                    mix > 0.0f ? (std::to_string(int(mix * 100.0f + 0.5f)) + " %").c_str() : "off", cells.c_str(), sum);
        std::fflush(stdout);
      }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
