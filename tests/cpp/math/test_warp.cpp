// Warps: Monte Carlo of 1/pdf over each warp's samples equals the measure of its domain, and the
// samples' histogram over cells of equal measure matches the stated pdf (which E[1/pdf] cannot
// check for a constant pdf).
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/math/distribution.h"
#include "core/math/rng.h"
#include "core/math/warp.h"

using namespace limn;

namespace {
// Mean and standard error of f over n samples.
template <typename F>
std::pair<double, double> mc(int n, F&& f) {
  double s = 0, s2 = 0;
  for (int i = 0; i < n; ++i) {
    const double v = f(i);
    s += v;
    s2 += v * v;
  }
  const double mean = s / n;
  return {mean, std::sqrt(std::max(0.0, s2 / n - mean * mean) / n)};
}
constexpr int kN = 200000;
}  // namespace

TEST_CASE("warps: E[1/pdf] equals the measure of the domain") {
  Pcg32 rng(7);
  SUBCASE("uniform sphere: 4 pi") {
    auto [m, e] = mc(kN, [&](int) {
      const Vec3 w = warp::square_to_uniform_sphere(rng.next_2d());
      CHECK(std::abs(glm::length(w) - 1.0f) < 1e-5f);
      return 1.0 / warp::square_to_uniform_sphere_pdf();
    });
    CHECK(m == doctest::Approx(4 * M_PI).epsilon(1e-6));
  }
  SUBCASE("uniform hemisphere: 2 pi") {
    auto [m, e] = mc(kN, [&](int) { return 1.0 / warp::square_to_uniform_hemisphere_pdf(warp::square_to_uniform_hemisphere(rng.next_2d())); });
    CHECK(m == doctest::Approx(2 * M_PI).epsilon(1e-6));
  }
  SUBCASE("cosine hemisphere: 2 pi (pdf > 0 on the open hemisphere)") {
    auto [m, e] = mc(kN, [&](int) {
      const Vec3 w = warp::square_to_cosine_hemisphere(rng.next_2d());
      const float pdf = warp::square_to_cosine_hemisphere_pdf(w);
      return pdf > 0 ? 1.0 / pdf : 0.0;
    });
    CHECK(std::abs(m - 2 * M_PI) < 5 * e);
  }
  SUBCASE("cone: 2 pi (1 - cos max)") {
    const float cos_max = 0.8f;
    auto [m, e] = mc(kN, [&](int) {
      const Vec3 w = warp::square_to_uniform_cone(rng.next_2d(), cos_max);
      CHECK(w.z >= cos_max - 1e-6f);
      return 1.0 / warp::square_to_uniform_cone_pdf(w, cos_max);
    });
    CHECK(m == doctest::Approx(2 * M_PI * (1 - cos_max)).epsilon(1e-5));
  }
  SUBCASE("concentric disk: area pi, and samples inside") {
    int inside = 0;
    for (int i = 0; i < kN; ++i) inside += glm::length(warp::square_to_disk_concentric(rng.next_2d())) <= 1.0f + 1e-6f;
    CHECK(inside == kN);
    CHECK(1.0 / warp::square_to_disk_concentric_pdf(Vec2(0.3f, 0.2f)) == doctest::Approx(M_PI));
  }
  SUBCASE("triangle: uniform over the unit triangle (mean barycentric 1/3)") {
    auto [m, e] = mc(kN, [&](int) {
      const Vec2 b = warp::square_to_uniform_triangle(rng.next_2d());
      CHECK(b.x >= 0.0f);
      CHECK(b.y >= 0.0f);
      CHECK(b.x + b.y <= 1.0f + 1e-6f);
      return double(b.x);
    });
    CHECK(std::abs(m - 1.0 / 3.0) < 5 * e);
  }
}

namespace {
// Pearson's chi-square of kN samples of a warp over nz x nphi cells of (z, phi) (z in [z0, z1], phi
// the azimuth in [0, 2 pi)), against the probabilities the warp's stated pdf gives the cells: pdf at
// the cell's centre times its solid angle dz dphi (exact for pdfs constant or linear in z, all of
// the warps here). E[1/pdf] cannot tell a constant pdf from a sampler that puts its points
// anywhere in the domain; the histogram can. `outside` counts samples off the unit sphere or
// outside [z0, z1]; `total` is the cells' summed probability (1 for a normalised pdf).
struct Histogram {
  double chi2 = 0, total = 0;
  int outside = 0, dof = 0;
};
template <typename Sample, typename Pdf>
Histogram zphi_histogram(Sample&& sample, Pdf&& pdf, double z0, double z1, int nz = 8, int nphi = 16) {
  std::vector<double> counts(size_t(nz * nphi), 0.0);
  Histogram h;
  for (int i = 0; i < kN; ++i) {
    const Vec3 w = sample();
    if (std::abs(glm::length(w) - 1.0f) > 1e-5f || w.z < z0 - 1e-6 || w.z > z1 + 1e-6) {
      ++h.outside;
      continue;
    }
    double phi = std::atan2(double(w.y), double(w.x));
    if (phi < 0) phi += 2 * M_PI;
    const int iz = std::clamp(int((w.z - z0) / (z1 - z0) * nz), 0, nz - 1);
    const int ip = std::clamp(int(phi / (2 * M_PI) * nphi), 0, nphi - 1);
    counts[size_t(iz * nphi + ip)] += 1;
  }
  const double dz = (z1 - z0) / nz, dphi = 2 * M_PI / nphi;
  for (int iz = 0; iz < nz; ++iz) {
    for (int ip = 0; ip < nphi; ++ip) {
      const double z = z0 + (iz + 0.5) * dz, phi = (ip + 0.5) * dphi, r = std::sqrt(std::max(0.0, 1 - z * z));
      const Vec3 mid(float(r * std::cos(phi)), float(r * std::sin(phi)), float(z));
      const double p = double(pdf(mid)) * dz * dphi;
      h.total += p;
      const double expected = kN * p;
      const double d = counts[size_t(iz * nphi + ip)] - expected;
      h.chi2 += d * d / expected;
    }
  }
  h.dof = nz * nphi - 1;
  return h;
}
// Far in the upper tail of chi-square with dof degrees of freedom (about 5 standard deviations).
double chi2_limit(int dof) { return dof + 5.0 * std::sqrt(2.0 * dof); }
}  // namespace

TEST_CASE("warps: sampled points follow the stated pdf (chi-square over cells of equal solid angle)") {
  Pcg32 rng(11);
  SUBCASE("uniform sphere") {
    const Histogram h = zphi_histogram([&] { return warp::square_to_uniform_sphere(rng.next_2d()); },
                                       [](const Vec3&) { return warp::square_to_uniform_sphere_pdf(); }, -1.0, 1.0);
    CHECK(h.outside == 0);
    CHECK(h.total == doctest::Approx(1.0).epsilon(1e-5));
    CHECK(h.chi2 < chi2_limit(h.dof));
  }
  SUBCASE("uniform hemisphere") {
    const Histogram h = zphi_histogram([&] { return warp::square_to_uniform_hemisphere(rng.next_2d()); },
                                       [](const Vec3& w) { return warp::square_to_uniform_hemisphere_pdf(w); }, 0.0, 1.0);
    CHECK(h.outside == 0);
    CHECK(h.total == doctest::Approx(1.0).epsilon(1e-5));
    CHECK(h.chi2 < chi2_limit(h.dof));
  }
  SUBCASE("cosine hemisphere") {
    const Histogram h = zphi_histogram([&] { return warp::square_to_cosine_hemisphere(rng.next_2d()); },
                                       [](const Vec3& w) { return warp::square_to_cosine_hemisphere_pdf(w); }, 0.0, 1.0);
    CHECK(h.outside == 0);
    CHECK(h.total == doctest::Approx(1.0).epsilon(1e-5));
    CHECK(h.chi2 < chi2_limit(h.dof));
  }
  SUBCASE("cone") {
    const float cos_max = 0.8f;
    const Histogram h = zphi_histogram([&] { return warp::square_to_uniform_cone(rng.next_2d(), cos_max); },
                                       [&](const Vec3& w) { return warp::square_to_uniform_cone_pdf(w, cos_max); }, cos_max, 1.0);
    CHECK(h.outside == 0);
    CHECK(h.total == doctest::Approx(1.0).epsilon(1e-5));
    CHECK(h.chi2 < chi2_limit(h.dof));
  }
  SUBCASE("concentric disk, lifted to the hemisphere") {
    // A point p of the disk lifted to (p, sqrt(1 - |p|^2)) has z^2 = 1 - r^2, so cells of equal
    // (z^2, phi) have equal area on the disk: the stated area pdf 1/pi over a cell is a probability
    // of pdf * dz^2 dphi / 2, i.e. the lifted pdf in solid angle is pdf(p) * z.
    const Histogram h = zphi_histogram(
        [&] {
          const Vec2 p = warp::square_to_disk_concentric(rng.next_2d());
          return Vec3(p.x, p.y, safe_sqrt(1.0f - glm::dot(p, p)));
        },
        [](const Vec3& w) { return warp::square_to_disk_concentric_pdf(Vec2(w.x, w.y)) * w.z; }, 0.0, 1.0);
    CHECK(h.outside == 0);
    CHECK(h.total == doctest::Approx(1.0).epsilon(1e-5));
    CHECK(h.chi2 < chi2_limit(h.dof));
  }
  SUBCASE("triangle: (1 - (1 - b1)^2, b2 / (1 - b1)) is uniform on the square for density 2") {
    // Mapped to the sphere's (z, phi) so the same histogram applies: z = 2 u - 1, phi = 2 pi v.
    const Histogram h = zphi_histogram(
        [&] {
          const Vec2 b = warp::square_to_uniform_triangle(rng.next_2d());
          const double u = 1.0 - (1.0 - b.x) * (1.0 - b.x), v = b.x < 1.0f ? b.y / (1.0 - b.x) : 0.0;
          const double z = 2 * u - 1, r = std::sqrt(std::max(0.0, 1 - z * z)), phi = 2 * M_PI * std::min(v, 1.0 - 1e-9);
          return Vec3(float(r * std::cos(phi)), float(r * std::sin(phi)), float(z));
        },
        [](const Vec3&) { return float(1.0 / (4 * M_PI)); }, -1.0, 1.0);
    CHECK(h.outside == 0);
    CHECK(h.chi2 < chi2_limit(h.dof));
  }
  SUBCASE("the check can fail: cosine-distributed points against the uniform hemisphere's pdf, and a cone of the wrong angle") {
    const Histogram cosine = zphi_histogram([&] { return warp::square_to_cosine_hemisphere(rng.next_2d()); },
                                            [](const Vec3& w) { return warp::square_to_uniform_hemisphere_pdf(w); }, 0.0, 1.0);
    CHECK(cosine.chi2 > 100 * chi2_limit(cosine.dof));
    const Histogram cone = zphi_histogram([&] { return warp::square_to_uniform_cone(rng.next_2d(), 0.85f); },
                                          [](const Vec3& w) { return warp::square_to_uniform_cone_pdf(w, 0.8f); }, 0.8, 1.0);
    CHECK(cone.chi2 > 10 * chi2_limit(cone.dof));
  }
}

TEST_CASE("distributions: pdfs integrate to 1 and sampling frequencies match the pmf") {
  const std::vector<float> w = {1.0f, 0.0f, 3.0f, 0.5f, 2.0f};
  Distribution1D d(w);
  double integral = 0;
  for (size_t i = 0; i < w.size(); ++i) integral += d.pmf(i);
  CHECK(integral == doctest::Approx(1.0));
  std::vector<int> counts(w.size(), 0);
  Pcg32 rng(3);
  const int n = 100000;
  for (int i = 0; i < n; ++i) {
    size_t bin;
    float pdf;
    const float x = d.sample_continuous(rng.next_float(), &bin, &pdf);
    CHECK(x >= 0.0f);
    CHECK(x < 1.0f);
    CHECK(size_t(x * w.size()) == bin);
    CHECK(pdf == doctest::Approx(d.pdf(x)));
    counts[bin]++;
  }
  CHECK(counts[1] == 0);  // zero-weight bins are never chosen
  for (size_t i = 0; i < w.size(); ++i) {
    const double p = d.pmf(i), sigma = std::sqrt(n * p * (1 - p));
    CHECK(std::abs(counts[i] - n * p) <= 5 * sigma + 1);
  }

  std::vector<float> w2(6 * 4);
  for (size_t i = 0; i < w2.size(); ++i) w2[i] = float((i * 7) % 5);
  Distribution2D d2(w2, 6, 4);
  auto [m, e] = mc(200000, [&](int) { return double(d2.pdf(rng.next_2d())); });  // integral of pdf over [0,1)^2
  CHECK(std::abs(m - 1.0) < 5 * e);
  for (int i = 0; i < 1000; ++i) {
    float pdf;
    const Vec2 uv = d2.sample(rng.next_2d(), &pdf);
    CHECK(pdf == doctest::Approx(d2.pdf(uv)).epsilon(1e-4));
    CHECK(pdf > 0.0f);
  }
}
