// Relative variance of the indirect boundary estimate under each projective guide, rare tails
// included: `limn_guide_variance scene.json param [--seeds K] [--qspp N] [--spp B] [--grid-mix X]
// [--direction-resolution D]` (the last two set DiffOptions::octree_grid_mix and
// direction_resolution of the guides under test, not of the wide proposal).
//
// A render of a few million samples rarely meets a guide's worst region (an edge's specular peak
// that no projection reached), so render errors over a few runs hide it. Here the second moment
// E_p[(f/p)^2] = E_q[f^2 / (p q)] of every guide p is estimated from N samples per pixel of one
// wide proposal q (four default octree guides from other seeds, mixed), which covers what any one
// guide misses; q's own relative variance is printed as a check. The integrand f is the guides'
// (IndirectBoundary::guide_value, without the tangent's velocity). Also printed: the least relative
// variance any grid of the default shape can reach, from the same samples. Markdown on stdout.
// `--tail K` also lists the K samples that carry most of the default octree's (first seed) second
// moment: where on which segment, towards which direction, f and the guide's density there.
// The derivative image (x translation) is measured the same way: each guide's image variance per
// sample, the run-to-run noise it predicts at the budget, and the floor no density can beat.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include "core/diff/terms/indirect.h"
#include "core/diff/render_diff.h"
#include "core/guiding/grid.h"
#include "core/guiding/mixture.h"
#include "core/io/scene_loader.h"
#include "core/math/rng.h"

using namespace limn;

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s scene.json param [--seeds K] [--qspp N] [--spp B] [--tail K] [--grid-mix X] [--direction-resolution D] [--direction-octaves K] [--leaf-samples N] [--refine-rounds R] [--refine-factor F] [--refine-depth D] [--max-leaves N] [--octree-depth D] [--guiding-seeds N] [--octree-training N]\n", argv[0]);
    return 2;
  }
  int seeds = 4, qspp = 2048, spp = 1024, tail = 0;
  DiffOptions tested;  // settings of the guides under test
  for (int a = 3; a + 1 < argc; a += 2) {
    const std::string k = argv[a];
    if (k == "--seeds") seeds = std::stoi(argv[a + 1]);
    else if (k == "--qspp") qspp = std::stoi(argv[a + 1]);
    else if (k == "--spp") spp = std::stoi(argv[a + 1]);
    else if (k == "--tail") tail = std::stoi(argv[a + 1]);
    else if (k == "--grid-mix") tested.octree_grid_mix = std::stof(argv[a + 1]);
    else if (k == "--direction-resolution") tested.direction_resolution = std::stoi(argv[a + 1]);
    else if (k == "--direction-octaves") tested.direction_octaves = std::stoi(argv[a + 1]);
    else if (k == "--leaf-samples") tested.octree.leaf_samples = std::stoi(argv[a + 1]);
    else if (k == "--refine-rounds") tested.octree.refine_rounds = std::stoi(argv[a + 1]);
    else if (k == "--refine-factor") tested.octree.refine_factor = std::stof(argv[a + 1]);
    else if (k == "--max-leaves") tested.octree.max_leaves = size_t(std::stoull(argv[a + 1]));
    else if (k == "--refine-depth") tested.octree.refine_depth = std::stoi(argv[a + 1]);
    else if (k == "--refine-neighbours") tested.octree.refine_neighbours = std::stoi(argv[a + 1]) != 0;
    else if (k == "--octree-depth") tested.octree.max_depth = std::stoi(argv[a + 1]);
    else if (k == "--guiding-seeds") tested.guiding_seeds = std::stoi(argv[a + 1]);
    else if (k == "--octree-training") tested.octree_training = std::stoi(argv[a + 1]);
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
    base.spp_boundary = spp;  // the projective grid's seed paths follow the boundary budget (seeds_per_pixel)
    auto options = [&](const std::string& guiding, float direction_mix, uint64_t seed, bool under_test = false) {
      DiffOptions o = base;
      if (under_test) {
        o.octree_grid_mix = tested.octree_grid_mix;
        o.direction_resolution = tested.direction_resolution;
        o.direction_octaves = tested.direction_octaves;
        o.octree.leaf_samples = tested.octree.leaf_samples;
        o.octree.max_depth = tested.octree.max_depth;
        o.octree.refine_rounds = tested.octree.refine_rounds;
        o.octree.refine_factor = tested.octree.refine_factor;
        o.octree.refine_depth = tested.octree.refine_depth;
        o.octree.refine_neighbours = tested.octree.refine_neighbours;
        o.octree.max_leaves = tested.octree.max_leaves;
        o.guiding_seeds = tested.guiding_seeds;
        o.octree_training = tested.octree_training;
      }
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
    std::vector<double> fq(M, 0.0);   // f / q, 0 where f or q is not usable
    std::vector<double> f2q(M, 0.0);  // f^2 / q = (f/q)^2 q: E_q[f2q / p] = E_p[(f/p)^2]
    // The image's integrand: the sample's derivative image g (every splat's value times its
    // velocity along the tangent, x translation), as render_forward adds it. Kept per sample:
    // |g|^2 q (E_q[|g|^2 q / p] = E_p[|f/p|^2] for any guide p) and |g|; summed: the image E_q[g].
    std::vector<double> g2q(M, 0.0), gnorm(M, 0.0);
    std::vector<double> tangent(params.slot_count(), 0.0);
    for (size_t s = 0; s < tangent.size(); s += 3) tangent[s] = 1.0;
    const size_t pixels = size_t(scene->camera.width) * scene->camera.height;
    tbb::enumerable_thread_specific<std::vector<double>> images(std::vector<double>(3 * pixels, 0.0));
    tbb::parallel_for(size_t(0), M, [&](size_t i) {
      Pcg32 rng = pixel_rng(mix_bits(424242), i);
      float pdf;
      u[i] = q->sample(Vec3d(rng.next_double(), rng.next_float(), rng.next_float()), &pdf);
      const float f = ib.guide_value(u[i]);
      if (pdf > 0.0f && std::isfinite(f) && f > 0.0f) {
        fq[i] = double(f) / pdf;
        f2q[i] = fq[i] * double(f);
      }
      if (!(pdf > 0.0f)) return;
      ad::Tape::current().clear();
      PathInputs in;
      std::vector<IndirectBoundary::Splat> splats;
      std::vector<ad::Var> vel;
      uint64_t rays = 0;
      ib.sample_at(u[i], pdf, q->pdf_first(u[i].x), rng, in, splats, vel, rays);
      std::vector<double> d(vel.size(), 0.0), adj;
      for (size_t k = 0; k < vel.size(); ++k) {
        if (vel[k].is_constant()) continue;
        ad::Tape::current().backward(vel[k].idx, 1.0, adj);
        for (const auto& [node, slot] : in.nodes) d[k] += adj[node] * tangent[slot];
      }
      std::map<size_t, double> g;  // (pixel, channel) -> value of this sample
      for (const auto& sp : splats)
        for (int c = 0; c < 3; ++c) g[3 * size_t(sp.pixel) + c] += double(sp.value[c]) * d[size_t(sp.velocity)];
      double n2 = 0.0;
      for (const auto& [k, v] : g) n2 += v * v;
      if (!std::isfinite(n2)) return;  // counted as zero, as render_forward drops it
      std::vector<double>& im = images.local();
      for (const auto& [k, v] : g) im[k] += v / double(M);
      g2q[i] = n2 * pdf;
      gnorm[i] = std::sqrt(n2);
    });
    ad::Tape::current().clear();
    std::vector<double> image(3 * pixels, 0.0);
    for (const auto& im : images)
      for (size_t k = 0; k < image.size(); ++k) image[k] += im[k];
    double image2 = 0.0, mean_norm = 0.0;
    for (double v : image) image2 += v * v;
    for (double v : gnorm) mean_norm += v / double(M);
    double F = 0.0, s2 = 0.0;
    for (double w : fq) {
      F += w / double(M);
      s2 += w * w / double(M);
    }
    std::printf("%s, `%s`: integral %.4g from %zu samples of the wide proposal (its own relative variance %.1f)\n\n", scene->source.c_str(),
                argv[2], F, M, s2 / (F * F) - 1.0);
    // What any grid of the default shape could reach, from the same samples: a cell c's
    // probability P_c uniform inside it gives E[(f/p)^2] = sum_c (int_c f^2) V_c / P_c (V_c its
    // volume), least at P_c ~ sqrt(V_c int_c f^2); the grid of exact cell integrals (with the
    // guides' 10 % defensive share) is what a perfect cell-mass estimate would give.
    {
      const std::array<int, 3> res = grid_cells(base);
      const BoundaryGrid cells(res, {}, {});  // only its cell layout
      const size_t n = cells.cell_count();
      std::vector<double> integral(n, 0.0), second(n, 0.0);
      for (size_t i = 0; i < M; ++i) {
        if (fq[i] == 0.0) continue;
        const size_t c = cells.region_of(u[i]);
        integral[c] += fq[i] / double(M);
        second[c] += f2q[i] / double(M);  // int_c f^2 = E_q[f^2 / q 1_c]
      }
      const double V = 1.0 / double(n);
      double root = 0.0, exact = 0.0;
      for (size_t c = 0; c < n; ++c) {
        root += std::sqrt(V * second[c]);
        if (second[c] > 0.0) exact += V * second[c] / (0.9 * integral[c] / F + 0.1 * V);
      }
      std::printf("Bounds for a %dx%dx%d grid from these samples: relative variance %.0f with each cell's probability ~ sqrt(V int f^2) "
                  "(the least any such grid can have), %.0f with exact cell integrals and the 10 %% defensive share.\n\n",
                  res[0], res[1], res[2], root * root / (F * F) - 1.0, exact / (F * F) - 1.0);
    }
    // The derivative image's variance per sample, Var_p = E_p[|f/p|^2] - |I|^2 summed over pixels
    // and channels, relative to |I|^2. No density does better than p ~ |f| (independent samples),
    // whose Var is (int |f|)^2 - |I|^2; computed with E|f| where f is random (path-traced L_d and
    // importance), so it is at most the true floor (int sqrt(E|f|^2))^2 - |I|^2.
    const double n_render = double(spp) * double(pixels);
    auto noise = [&](double rv) { return std::sqrt(std::max(rv, 0.0) / n_render); };
    const double floor_rv = mean_norm * mean_norm / image2 - 1.0;
    double q_image_m2 = 0.0, ideal_image_m2 = 0.0;  // E_p[|f/p|^2] for q, and for p = f / F (the guides' ideal)
    for (size_t i = 0; i < M; ++i) {
      q_image_m2 += gnorm[i] * gnorm[i] / double(M);
      if (fq[i] > 0.0) ideal_image_m2 += F * gnorm[i] * gnorm[i] / fq[i] / double(M);  // |g|^2 q / p, p = f / F = fq q / F
    }
    std::printf("Derivative image (x translation): relative variance per sample %.0f for the wide proposal, %.0f for the best "
                "density any guide could have (p ~ |f|, independent samples), %.0f for the density the guides aim at (p ~ the guides' "
                "integrand, without the velocity); at %d spp the best density's run-to-run noise is %.4f of the image's RMS.\n\n",
                q_image_m2 / image2 - 1.0, floor_rv, ideal_image_m2 / image2 - 1.0, spp, noise(floor_rv));
    std::printf("| guide | direction histogram | relative variance per guide seed | mean | derivative image: relative variance per guide seed | mean | noise at %d spp | over the best density |\n"
                "|---|---|---|---|---|---|---|---|\n", spp);
    for (const std::string guiding : {"grid", "octree"})
      for (const float mix : {0.0f, kDirectionMix}) {
        std::string cells, image_cells;
        double sum = 0.0, image_sum = 0.0;
        for (int t = 0; t < seeds; ++t) {
          const auto built_at = std::chrono::steady_clock::now();
          const auto p = build_boundary_guide(*scene, ib, options(guiding, mix, 7 + 1000 * uint64_t(t), true));
          std::fprintf(stderr, "%s (direction share %.2f, seed %d): built in %.2f s: %s\n", guiding.c_str(), mix, t,
                       std::chrono::duration<double>(std::chrono::steady_clock::now() - built_at).count(), p->describe().c_str());
          std::vector<double> part(M), image_part(M);
          tbb::parallel_for(size_t(0), M, [&](size_t i) {
            const float pu = p->pdf(u[i]);
            part[i] = pu > 0.0f ? f2q[i] / pu : 0.0;
            image_part[i] = pu > 0.0f ? g2q[i] / pu : 0.0;
          });
          double m2 = 0.0, image_m2 = 0.0;
          for (size_t i = 0; i < M; ++i) {
            m2 += part[i] / double(M);
            image_m2 += image_part[i] / double(M);
          }
          const double rv = m2 / (F * F) - 1.0, image_rv = image_m2 / image2 - 1.0;
          sum += rv / seeds;
          image_sum += image_rv / seeds;
          cells += (t ? " " : "") + std::to_string(int(std::lround(rv)));
          image_cells += (t ? " " : "") + std::to_string(int(std::lround(image_rv)));
        }
        std::printf("| %s | %s | %s | %.0f | %s | %.0f | %.4f | %.2fx |\n", guiding == "grid" ? "projective grid" : "octree",
                    mix > 0.0f ? (std::to_string(int(mix * 100.0f + 0.5f)) + " %").c_str() : "off", cells.c_str(), sum,
                    image_cells.c_str(), image_sum, noise(image_sum), noise(image_sum) / noise(floor_rv));
        std::fflush(stdout);
      }
    if (tail > 0) {
      // Each sample's share of E_p[(f/p)^2] = E_q[f^2 / (p q)] for the default octree guide.
      const auto p = build_boundary_guide(*scene, ib, options("octree", kDirectionMix, 7, true));
      std::vector<double> share(M, 0.0);
      double m2 = 0.0;
      for (size_t i = 0; i < M; ++i) {
        const float pu = p->pdf(u[i]);
        share[i] = pu > 0.0f ? f2q[i] / pu / double(M) : 0.0;
        m2 += share[i];
      }
      std::vector<size_t> order(M);
      for (size_t i = 0; i < M; ++i) order[i] = i;
      const size_t K = std::min(M, size_t(tail));
      std::partial_sort(order.begin(), order.begin() + K, order.end(), [&](size_t a, size_t b) { return share[a] > share[b]; });
      std::printf("\nSamples carrying most of the default octree's second moment (guide seed 7; f / F with F the integral, "
                  "p the guide's density on [0,1)^3):\n\n| share | u | segment | lambda or normal | w | f / F | p |\n|---|---|---|---|---|---|---|\n");
      for (size_t k = 0; k < K; ++k) {
        const size_t i = order[k];
        BoundaryPoint b;
        const bool ok = ib.space().sample(u[i], 1.0f, b);
        std::printf("| %.2g %% | %.6f %.5f %.5f | %d | %.4f %.4f %.4f | %.4f %.4f %.4f | %.3g | %.4g |\n", 100.0 * share[i] / m2,
                    u[i].x, u[i].y, u[i].z, ok ? b.segment : -1, b.param.x, b.param.y, b.param.z, b.w.x, b.w.y, b.w.z,
                    fq[i] * q->pdf(u[i]) / F, p->pdf(u[i]));
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
