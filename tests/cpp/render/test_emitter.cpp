// Emitters: environment-map importance sampling agrees with uniform sampling; area emitter pdfs.
#include <doctest/doctest.h>

#include "core/math/rng.h"
#include "core/math/warp.h"
#include "core/render/emitters/emitter.h"

using namespace limn;

namespace {
EnvmapEmitter make_env() {
  EnvmapEmitter env;
  env.image = std::make_shared<Bitmap>();
  Bitmap& b = *env.image;
  b.width = 32;
  b.height = 16;
  b.rgb.assign(size_t(b.width) * b.height * 3, 0.05f);
  for (int y = 3; y < 6; ++y)  // a bright patch, like a sun
    for (int x = 20; x < 23; ++x)
      for (int c = 0; c < 3; ++c) b.rgb[3 * (size_t(y) * b.width + x) + c] = 50.0f;
  env.world_from_env = Transform::rotate(Vec3d(1, 0, 0), 90.0);  // the map's +y becomes world +z
  env.build_distribution();
  return env;
}
}  // namespace

TEST_CASE("envmap: pdf integrates to 1 and matches what sample() reports") {
  const EnvmapEmitter env = make_env();
  Pcg32 rng(2);
  const int n = 400000;
  double integral = 0, s2 = 0;
  for (int i = 0; i < n; ++i) {
    const double v = env.pdf_solid_angle(warp::square_to_uniform_sphere(rng.next_2d())) * 4 * M_PI;
    integral += v;
    s2 += v * v;
  }
  integral /= n;
  const double err = std::sqrt((s2 / n - integral * integral) / n);
  CHECK(std::abs(integral - 1.0) < 5 * err);
  for (int i = 0; i < 2000; ++i) {
    float pdf;
    const Vec3 d = env.sample(rng.next_2d(), &pdf);
    CHECK(glm::length(d) == doctest::Approx(1.0f).epsilon(1e-5));
    if (pdf > 1e-3f) CHECK(env.pdf_solid_angle(d) == doctest::Approx(pdf).epsilon(2e-3));
  }
}

TEST_CASE("envmap: importance sampling agrees with uniform sampling") {
  const EnvmapEmitter env = make_env();
  // Irradiance at an upward-facing point: E = integral of L(w) max(0, w.z) dw.
  Pcg32 rng(4);
  const int n = 400000;
  double imp = 0, imp2 = 0, uni = 0, uni2 = 0;
  for (int i = 0; i < n; ++i) {
    float pdf;
    const Vec3 d = env.sample(rng.next_2d(), &pdf);
    const double v = pdf > 0 ? env.eval(d).x * std::max(0.0f, d.z) / pdf : 0.0;
    imp += v;
    imp2 += v * v;
    const Vec3 u = warp::square_to_uniform_sphere(rng.next_2d());
    const double w = env.eval(u).x * std::max(0.0f, u.z) * 4 * M_PI;
    uni += w;
    uni2 += w * w;
  }
  imp /= n;
  uni /= n;
  const double e_imp = std::sqrt((imp2 / n - imp * imp) / n), e_uni = std::sqrt((uni2 / n - uni * uni) / n);
  CAPTURE(imp);
  CAPTURE(uni);
  CHECK(std::abs(imp - uni) < 5 * (e_imp + e_uni));
  CHECK(e_imp < 0.5 * e_uni);  // and it is the better estimator
}

TEST_CASE("area emitter: sampled solid-angle pdf matches pdf_emitter_area") {
  Mesh m;
  m.positions = {-1, -1, 2, 1, -1, 2, 1, 1, 2, -1, 1, 2};
  m.indices = {0, 2, 1, 0, 3, 2};  // faces -z, towards the origin
  m.face_normals = true;
  m.update_derived();
  std::vector<Shape> shapes(1);
  shapes[0].geometry = m;
  Emitter e{"lamp", AreaEmitter{0, Spectrum(3.0f)}};
  Pcg32 rng(8);
  double irradiance = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    const Vec2 u = rng.next_2d();
    const EmitterSample s = sample_emitter(e, shapes, Vec3(0.0f), u, rng.next_float());
    REQUIRE(s.pdf > 0);
    CHECK(pdf_emitter_area(e, shapes[0], Vec3(0.0f), s.p, Vec3(0, 0, -1)) == doctest::Approx(s.pdf).epsilon(1e-4));
    irradiance += s.radiance.x * s.wi.z / s.pdf;
  }
  // Irradiance from a uniform square of side 2 at height 2 (closed form for a rectangle seen from
  // below its corner, four times): E = L * 4 * (a/sqrt(h^2+a^2)) atan(a/sqrt(h^2+a^2)) ... summed.
  const double a = 1, h = 2;
  const double A = a / std::sqrt(a * a + h * h);
  const double quarter = 0.5 * (A * std::atan(A) + A * std::atan(A));  // form factor of a corner rectangle times pi
  const double expected = 3.0 * 4.0 * quarter;
  CHECK(irradiance / n == doctest::Approx(expected).epsilon(0.01));
}
