// Warps: Monte Carlo of 1/pdf over each warp's samples equals the measure of its domain.
#include <doctest/doctest.h>

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
