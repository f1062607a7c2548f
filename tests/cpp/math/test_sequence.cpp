// The boundary terms' stratified points (core/math/sequence.h): nets, uniform points, and an
// unbiased estimate with less variance than independent points.
#include <doctest/doctest.h>

#include <map>
#include <vector>
#include "core/math/sequence.h"

using namespace limn;

namespace {
// Points j = 0 .. n-1 of one sequence.
std::vector<Vec3d> points(uint64_t n, uint64_t seed) {
  const StratifiedSequence3 seq(n, seed);
  Pcg32 rng(seed);
  std::vector<Vec3d> p;
  for (uint64_t j = 0; j < n; ++j) p.push_back(seq.point(j, rng));
  return p;
}
}  // namespace

TEST_CASE("stratified sequence: 2^m points form a (0, m, 3)-net, scrambled or not") {
  constexpr int m = 9;
  constexpr uint64_t n = uint64_t(1) << m;
  for (uint64_t seed : {1ull, 2ull, 77ull}) {
    const std::vector<Vec3d> p = points(n, seed);
    // Every elementary box of volume 2^-m (2^-a x 2^-b x 2^-c, a + b + c = m) holds one point.
    for (int a = 0; a <= m; ++a)
      for (int b = 0; a + b <= m; ++b) {
        const int c = m - a - b;
        std::map<uint64_t, int> count;
        for (const Vec3d& q : p) {
          CHECK((q.x >= 0.0 && q.x < 1.0 && q.y >= 0.0 && q.y < 1.0 && q.z >= 0.0 && q.z < 1.0));
          const uint64_t ix = uint64_t(q.x * double(1u << a)), iy = uint64_t(q.y * double(1u << b)), iz = uint64_t(q.z * double(1u << c));
          count[(ix << 40) | (iy << 20) | iz]++;
        }
        INFO("seed " << seed << ", box 2^-" << a << " x 2^-" << b << " x 2^-" << c);
        CHECK(count.size() == n);
      }
  }
  // The unscrambled Sobol dimensions alone are a (0, m, 2)-net too (the scramble keeps what is there).
  std::map<uint64_t, int> count;
  for (uint32_t i = 0; i < n; ++i) count[(uint64_t(sobol_dim0(i) >> (32 - 4)) << 32) | (sobol_dim1(i) >> (32 - (m - 4)))]++;
  CHECK(count.size() == n);
}

TEST_CASE("stratified sequence: each point is uniform over seeds (chi-square, 16 bins per axis)") {
  // Point j = 5 of 1000 over 16000 seeds: x uniform in its stratum [5, 6) / 1000, y and z over [0, 1).
  constexpr int kSeeds = 16000, kBins = 16;
  int bins[3][kBins] = {};
  for (int s = 0; s < kSeeds; ++s) {
    const StratifiedSequence3 seq(1000, mix_bits(uint64_t(s) + 1));
    Pcg32 rng(uint64_t(s) * 31 + 7);
    const Vec3d q = seq.point(5, rng);
    REQUIRE((q.x >= 0.005 && q.x < 0.006));
    bins[0][int((q.x - 0.005) / 0.001 * kBins)]++;
    bins[1][int(q.y * kBins)]++;
    bins[2][int(q.z * kBins)]++;
  }
  // 15 degrees of freedom: P(chi2 > 37.7) = 0.001.
  for (int a = 0; a < 3; ++a) {
    double chi2 = 0.0;
    const double expected = double(kSeeds) / kBins;
    for (int k = 0; k < kBins; ++k) chi2 += (bins[a][k] - expected) * (bins[a][k] - expected) / expected;
    INFO("axis " << a);
    CHECK(chi2 < 37.7);
  }
}

TEST_CASE("stratified sequence: an unbiased estimate of a step integrand, with less variance than independent points") {
  // f = 1 inside a tilted slab of [0,1)^3: a visibility-like discontinuity. Exact integral by a fine
  // midpoint rule over x and y (z's extent inside the slab is analytic).
  auto f = [](const Vec3d& q) { return (q.z < 0.3 + 0.4 * q.x * q.x + 0.2 * q.y) ? 1.0 : 0.0; };
  double exact = 0.0;
  constexpr int kQ = 2000;
  for (int i = 0; i < kQ; ++i)
    for (int k = 0; k < kQ; ++k) {
      const double x = (i + 0.5) / kQ, y = (k + 0.5) / kQ;
      exact += std::min(1.0, 0.3 + 0.4 * x * x + 0.2 * y) / (double(kQ) * kQ);
    }
  constexpr int kRuns = 400;
  constexpr uint64_t n = 1000;
  double s_strat = 0, s2_strat = 0, s_iid = 0, s2_iid = 0;
  for (int r = 0; r < kRuns; ++r) {
    const StratifiedSequence3 seq(n, mix_bits(uint64_t(r) + 99));
    Pcg32 rng(uint64_t(r) + 5), rng_iid(uint64_t(r) + 1234567);
    double est = 0, est_iid = 0;
    for (uint64_t j = 0; j < n; ++j) {
      est += f(seq.point(j, rng)) / n;
      est_iid += f(Vec3d(rng_iid.next_double(), rng_iid.next_double(), rng_iid.next_double())) / n;
    }
    s_strat += est, s2_strat += est * est, s_iid += est_iid, s2_iid += est_iid * est_iid;
  }
  const double mean = s_strat / kRuns, var = s2_strat / kRuns - mean * mean;
  const double mean_iid = s_iid / kRuns, var_iid = s2_iid / kRuns - mean_iid * mean_iid;
  INFO("exact " << exact << ", stratified " << mean << " (sd " << std::sqrt(var) << "), independent " << mean_iid << " (sd "
                << std::sqrt(var_iid) << ")");
  CHECK(std::abs(mean - exact) < 4.0 * std::sqrt(var / kRuns));
  CHECK(std::abs(mean_iid - exact) < 4.0 * std::sqrt(var_iid / kRuns));
  // A discontinuity across a 3D net: variance O(n^-4/3) against O(n^-1), so at n = 1000 about 10x less.
  CHECK(var < 0.25 * var_iid);
}
