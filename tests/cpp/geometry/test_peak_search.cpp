// Peak search (heightfield paper, Algorithm 1): the peaks equal the record local maxima of the slope
// found by dense sampling, with and without the mipmap; they are tangent points (Eq. 12); and rays
// just above / below a peak's slope miss / hit the surface near it, so the peaks are exactly where
// the ray tracer's visibility jumps.
#include <doctest/doctest.h>

#include "core/geometry/shapes/heightfield/peak_search.h"
#include "core/math/rng.h"

using namespace limn;

namespace {
Heightfield terrain(int n, uint64_t seed) {
  Heightfield hf;
  hf.nx = hf.ny = n;
  hf.width = hf.depth = 2.0f;
  hf.height_scale = 1.0f;
  Pcg32 rng(seed);
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c)
      hf.heights.push_back(0.15f * std::sin(0.45f * c + 0.3f * r) + 0.1f * std::cos(0.8f * r) + 0.04f * rng.next_float());
  hf.build_mipmap();
  return hf;
}

// Record local maxima of k over a dense sampling of the slice (reference).
std::vector<SlicePeak> dense_peaks(const Heightfield& hf, const Vec3d& o, const glm::dvec2& d, double k_start) {
  std::vector<SlicePeak> out;
  double t_end = 0;
  for (double t = 0; hf.inside(o.x + t * d.x, o.y + t * d.y); t += 1e-4) t_end = t;
  const int n = int(t_end / 2e-5);
  double run = k_start, run_before1 = k_start, k1 = -1e300, k2 = -1e300, t1 = 0;
  for (int i = 1; i <= n; ++i) {
    const double t = t_end * i / n, k = (hf.eval(o.x + t * d.x, o.y + t * d.y).z - o.z) / t;
    // k1 is a local maximum higher than everything before it.
    if (i >= 3 && k1 >= k2 && k1 > k && k1 > run_before1) out.push_back({t1, k1, false});
    run_before1 = run;
    run = std::max(run, k);
    k2 = k1;
    k1 = k;
    t1 = t;
  }
  return out;
}
// A slice from a random point of the surface (lifted by `lift`) at a random azimuth, and the slope
// of the tangent plane along it.
struct SurfaceSlice {
  Vec3d o;
  glm::dvec2 d;
  double k0;
};
SurfaceSlice random_slice(const Heightfield& hf, Pcg32& rng, double lift = 0.0) {
  const double x = (rng.next_float() - 0.5) * 1.6, y = (rng.next_float() - 0.5) * 1.6;
  const HeightSample h = hf.eval(x, y);
  const double phi = 6.283185307 * rng.next_float();
  const glm::dvec2 d(std::cos(phi), std::sin(phi));
  return {Vec3d(x, y, h.z + lift), d, h.dx * d.x + h.dy * d.y};
}
}  // namespace

TEST_CASE("peak search: peaks are the record slope maxima, with and without the mipmap") {
  const Heightfield hf = terrain(65, 3);
  Pcg32 rng(5);
  int total = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const auto [o, d, k0] = random_slice(hf, rng);
    PeakSearchStats fast_stats, slow_stats;
    const auto fast = find_peaks(hf, o, d, k0, 1e30, {}, &fast_stats);
    const auto slow = find_peaks(hf, o, d, k0, 1e30, {false, 4}, &slow_stats);
    const auto ref = dense_peaks(hf, o, d, k0);
    size_t interior = 0;
    for (const SlicePeak& p : fast) interior += !p.border;
    CHECK(interior == ref.size());
    REQUIRE(fast.size() == slow.size());
    for (size_t i = 0; i < fast.size(); ++i) CHECK(fast[i].k == doctest::Approx(slow[i].k).epsilon(1e-9));
    size_t j = 0;
    for (const SlicePeak& p : fast) {
      if (p.border || j >= ref.size()) continue;
      CHECK(p.t == doctest::Approx(ref[j].t).epsilon(2e-3));
      CHECK(p.k >= ref[j].k - 1e-9);  // refined: at least the dense maximum
      CHECK(p.k == doctest::Approx(ref[j].k).epsilon(1e-6));
      ++j;
      // Eq. 12: the line from the origin is tangent at the peak.
      const HeightSample q = hf.eval(o.x + p.t * d.x, o.y + p.t * d.y);
      CHECK(q.dx * d.x + q.dy * d.y == doctest::Approx(p.k).epsilon(1e-4));
    }
    for (size_t i = 1; i < fast.size(); ++i) CHECK(fast[i].k > fast[i - 1].k);
    CHECK(fast_stats.cells <= slow_stats.cells);
    total += int(ref.size());
  }
  CHECK(total > 20);
}

TEST_CASE("peak search: the curvature test finds the same peaks from far fewer cells on a fine smooth field") {
  // 513^2 heights of a smooth surface (no noise): near an origin on it the maximum test cannot
  // skip the cells the tangent line runs over; the second-derivative bound does.
  Heightfield hf;
  hf.nx = hf.ny = 513;
  for (int r = 0; r < hf.ny; ++r)
    for (int c = 0; c < hf.nx; ++c) hf.heights.push_back(0.15f * std::sin(0.02f * c + 0.013f * r) + 0.1f * std::cos(0.017f * r));
  hf.build_mipmap();
  Pcg32 rng(8);
  uint64_t cells_max = 0, cells_curv = 0, skips = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const auto [o, d, k0] = random_slice(hf, rng);
    PeakSearchStats with, without;
    const auto a = find_peaks(hf, o, d, k0, 1e30, {true, 4, true}, &with);
    const auto b = find_peaks(hf, o, d, k0, 1e30, {true, 4, false}, &without);
    REQUIRE(a.size() == b.size());
    for (size_t i = 0; i < a.size(); ++i) {
      CHECK(a[i].k == doctest::Approx(b[i].k).epsilon(1e-9));
      CHECK(a[i].t == doctest::Approx(b[i].t).epsilon(1e-6));
      CHECK(a[i].border == b[i].border);
    }
    cells_max += without.cells;
    cells_curv += with.cells;
    skips += with.curvature_hidden + with.curvature_rising;
    CHECK(without.curvature_hidden + without.curvature_rising == 0);
  }
  MESSAGE("cells: maximum test ", cells_max, ", with the curvature test ", cells_curv, " (", skips, " nodes skipped by it)");
  CHECK(skips > 0);
  CHECK(2 * cells_curv < cells_max);
}

TEST_CASE("peak search: visibility of the ray tracer jumps exactly at the peaks") {
  const Heightfield hf = terrain(49, 8);
  Pcg32 rng(9);
  int checked = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const auto [o, d, k0] = random_slice(hf, rng, 1e-6);
    for (const SlicePeak& p : find_peaks(hf, o, d, k0, 1e30)) {
      for (double dk : {1e-4, -1e-4}) {
        const Vec3d dir = glm::normalize(Vec3d(d.x, d.y, p.k + dk));
        double t;
        const bool hit = hf.intersect_local(o, dir, 1e-5, 10.0, t);
        const double horizontal = hit ? t * glm::length(glm::dvec2(dir.x, dir.y)) : 1e30;
        if (dk > 0) CHECK(horizontal > p.t * 0.999);  // passes over the peak
        else CHECK(horizontal <= p.t * 1.001);        // stopped by it (or before)
      }
      ++checked;
    }
  }
  CHECK(checked > 20);
}

TEST_CASE("peak search: a flat field has no peaks but its far edge; an origin outside sees the near edge") {
  Heightfield hf;
  hf.nx = hf.ny = 16;
  hf.heights.assign(256, 0.0f);
  hf.build_mipmap();
  const Vec3d o(0.1, -0.2, 0.0);
  auto peaks = find_peaks(hf, o, glm::dvec2(1, 0), 0.0, 1e30);
  CHECK(peaks.empty());  // k = 0 everywhere: never above the tangent plane
  // From above the plane the slope rises towards the far edge.
  peaks = find_peaks(hf, Vec3d(0.1, -0.2, 0.5), glm::dvec2(1, 0), -1e30, 1e30);
  REQUIRE(peaks.size() == 1);
  CHECK(peaks[0].border);
  CHECK(peaks[0].t == doctest::Approx(0.9));
  // From outside the footprint: the near edge first, then the far edge.
  peaks = find_peaks(hf, Vec3d(-3.0, 0.0, 0.5), glm::dvec2(1, 0), -1e30, 1e30);
  REQUIRE(peaks.size() == 2);
  CHECK(peaks[0].t == doctest::Approx(2.0));
  CHECK(peaks[1].t == doctest::Approx(4.0));
}

TEST_CASE("peak search: rays steeper than the last peak leave the field; 'blocked' means none does") {
  const Heightfield hf = terrain(49, 12);
  Pcg32 rng(21);
  int escaped = 0, blocked_count = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const auto [o, d, k0] = random_slice(hf, rng, 1e-6);
    const double k_stop = k0 + 0.4 * rng.next_float();
    bool blocked = false;
    const auto peaks = find_peaks(hf, o, d, k0, k_stop, {}, nullptr, &blocked);
    double t;
    if (blocked) {
      ++blocked_count;  // even the steepest ray of the range meets the field
      CHECK(hf.intersect_local(o, glm::normalize(Vec3d(d.x, d.y, k_stop - 1e-4)), 1e-5, 10.0, t));
    } else {
      const double k_top = peaks.empty() ? k0 : peaks.back().k;
      CHECK_FALSE(hf.intersect_local(o, glm::normalize(Vec3d(d.x, d.y, k_top + 1e-4)), 1e-5, 10.0, t));
      ++escaped;
    }
  }
  CHECK(escaped > 20);
  CHECK(blocked_count > 20);
}

TEST_CASE("parallel peak search: record maxima of z - k t along rays of one slope, where the ray tracer's visibility jumps") {
  // A directional light's slices: rays z = g + k_light t along d from outside the footprint.
  const Heightfield hf = terrain(49, 14);
  Pcg32 rng(23);
  int checked = 0, matched = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const double phi = 6.283185307 * rng.next_float(), u = (rng.next_float() - 0.5) * 1.6;
    const glm::dvec2 d(std::cos(phi), std::sin(phi));
    const Vec3d o(-2.0 * d.x - u * d.y, -2.0 * d.y + u * d.x, 0.0);  // 2 behind the centre, offset u sideways
    const double kl = -0.15 - 0.5 * rng.next_float();                // downwards: light from above
    PeakSearchStats fast_stats, slow_stats;
    const auto fast = find_parallel_peaks(hf, o, d, kl, {}, &fast_stats);
    const auto slow = find_parallel_peaks(hf, o, d, kl, {false, 4}, &slow_stats);
    REQUIRE(fast.size() == slow.size());
    CHECK(fast_stats.cells <= slow_stats.cells);
    REQUIRE(!fast.empty());
    CHECK(fast.front().border);  // the near edge
    // Dense reference of the interior records.
    double t_in = 1e30, t_out = 0;
    for (double t = 0; t < 5; t += 1e-4)
      if (hf.inside(o.x + t * d.x, o.y + t * d.y)) t_in = std::min(t_in, t), t_out = t;
    double run = -1e300, before = -1e300, g1 = -1e300, g2 = -1e300, t1 = 0;
    std::vector<SlicePeak> ref;
    for (double t = t_in + 2e-5; t < t_out; t += 2e-5) {
      const double g = hf.eval(o.x + t * d.x, o.y + t * d.y).z - kl * t;
      if (g2 > -1e300 && g1 >= g2 && g1 > g && g1 > before) ref.push_back({t1, g1, false});
      before = run;
      run = std::max(run, g);
      g2 = g1;
      g1 = g;
      t1 = t;
    }
    size_t j = 0;
    for (size_t i = 0; i < fast.size(); ++i) {
      CHECK(fast[i].k == doctest::Approx(slow[i].k).epsilon(1e-9));
      if (i > 0) CHECK(fast[i].k > fast[i - 1].k);
      const SlicePeak& p = fast[i];
      if (!p.border && j < ref.size()) {
        CHECK(p.t == doctest::Approx(ref[j].t).epsilon(2e-3));
        CHECK(p.k == doctest::Approx(ref[j].k).epsilon(1e-6));
        const HeightSample q = hf.eval(o.x + p.t * d.x, o.y + p.t * d.y);
        CHECK(q.dx * d.x + q.dy * d.y == doctest::Approx(kl).epsilon(1e-4));  // tangent: z' = k_light
        ++j, ++matched;
      }
      // Rays just above the grazing ray stay above the surface up to the peak; just below, they
      // meet it before the peak (dense sampling: the intersector misses some crossings of a 1e-3
      // deep chord at this field's sharp noise peaks, the search is what is tested here).
      if (p.border) continue;
      for (double dg : {1e-4, -1e-4}) {
        double first = 1e30;
        for (double t = 0; t < p.t + 0.05; t += 1e-5) {
          const double x = o.x + t * d.x, y = o.y + t * d.y;
          if (hf.inside(x, y) && p.k + dg + kl * t < hf.eval(x, y).z) {
            first = t;
            break;
          }
        }
        if (dg > 0) CHECK(first > p.t + 1e-3);  // none before (or just after) the peak
        else CHECK(first < p.t);
      }
      ++checked;
    }
    size_t interior = 0;
    for (const SlicePeak& p : fast) interior += !p.border;
    CHECK(interior == ref.size());
  }
  CHECK(matched > 10);
  CHECK(checked > 40);
}
