// The film's reconstruction filter and crop window (core/render/camera.h): the gaussian's sampler
// inverts its CDF, its integral is the quadrature of eval, splats carry a sample's unit weight,
// and a crop window's rays are the whole film's rays at the offset pixel.
#include <doctest/doctest.h>

#include <cmath>
#include "core/math/rng.h"
#include "core/render/camera.h"

using namespace limn;

namespace {

Camera camera(FilmFilter::Type type, double stddev = 0.5) {
  Camera c;
  c.world_from_camera = Transform();
  c.width = 24;
  c.height = 16;
  c.filter.type = type;
  c.filter.stddev = stddev;
  c.filter.radius = type == FilmFilter::Type::Box ? 0.5 : 4.0 * stddev;
  c.set_fov(40.0f, "x");
  return c;
}

// CDF of the filter by the midpoint rule on eval (independent of the closed form in sample()).
double cdf_by_quadrature(const FilmFilter& f, double x) {
  const int n = 20000;
  const double lo = -f.radius, h = (x - lo) / n;
  double s = 0.0;
  for (int i = 0; i < n; ++i) s += f.eval(lo + (i + 0.5) * h);
  return s * h / f.integral();
}

}  // namespace

TEST_CASE("film filter: the gaussian's integral is its quadrature and sample() inverts its CDF") {
  for (double stddev : {0.25, 0.5, 1.5}) {
    const FilmFilter f = camera(FilmFilter::Type::Gaussian, stddev).filter;
    CHECK(cdf_by_quadrature(f, f.radius) == doctest::Approx(1.0).epsilon(1e-6));
    CHECK(f.eval(f.radius) == 0.0);
    CHECK(f.eval(0.0) > 0.0);
    for (double u : {0.001, 0.1, 0.3, 0.5, 0.77, 0.999}) {
      const double x = f.sample(u);
      CHECK(std::abs(x) < f.radius);
      CHECK(cdf_by_quadrature(f, x) == doctest::Approx(u).epsilon(1e-5));
    }
  }
}

TEST_CASE("film filter: a splat spreads one unit of weight over the pixels the filter covers") {
  for (FilmFilter::Type type : {FilmFilter::Type::Box, FilmFilter::Type::Gaussian}) {
    const Camera c = camera(type);
    Pcg32 rng(3);
    // Averaged over positions inside the film, away from its edges, the weights sum to 1 (a sum
    // at one position varies: the gaussian sampled at integer offsets is not exactly normalised).
    double total = 0.0;
    const int n = 20000;
    for (int i = 0; i < n; ++i) {
      const double fx = 4.0 + 16.0 * rng.next_float(), fy = 4.0 + 8.0 * rng.next_float();
      c.splat(fx, fy, [&](int pixel, float w) {
        CHECK(pixel >= 0);
        CHECK(pixel < c.width * c.height);
        CHECK(w > 0.0f);
        total += w;
      });
    }
    CHECK(total / n == doctest::Approx(1.0).epsilon(2e-3));
    // Nothing beyond the filter's reach of the image.
    int count = 0;
    c.splat(-c.filter.radius - 0.01, 5.0, [&](int, float) { ++count; });
    c.splat(5.0, c.height + c.filter.radius + 0.01, [&](int, float) { ++count; });
    CHECK(count == 0);
    CHECK(!c.film_covers(-c.filter.radius - 0.01, 5.0));
  }
}

TEST_CASE("crop window: its rays are the whole film's at the offset pixel") {
  Camera full = camera(FilmFilter::Type::Box);
  Camera crop = full;
  crop.full_width = full.width;
  crop.full_height = full.height;
  crop.crop_x = 5;
  crop.crop_y = 3;
  crop.width = 8;
  crop.height = 6;
  for (const Vec2 p : {Vec2(0.0f, 0.0f), Vec2(3.25f, 5.5f), Vec2(7.9f, 0.1f)}) {
    const Ray a = crop.generate_ray(p), b = full.generate_ray(p + Vec2(5.0f, 3.0f));
    CHECK(glm::length(a.d - b.d) < 1e-6f);
  }
}
