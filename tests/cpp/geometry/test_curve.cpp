// Fibre curves' local geometry (core/geometry/shapes/curve.h): the frame, the fundamental forms and
// the normal curvature (frame independent, with F), the silhouette equation, the refined normal.
#include <doctest/doctest.h>

#include "core/geometry/shapes/curve.h"
#include "core/math/rng.h"

using namespace limn;

namespace {

// A bent curve with strongly varying radius, 3 spans.
BSplineCurve bent() {
  BSplineCurve c;
  c.control_points = {-0.8f, 0.0f, -0.2f, 0.10f, -0.5f, 0.2f, 0.05f, 0.13f, -0.2f, -0.1f, 0.25f, 0.15f,
                      0.1f,  0.15f, 0.15f, 0.14f, 0.35f, -0.05f, -0.05f, 0.1f, 0.6f, 0.2f, 0.05f, 0.18f};
  c.curve_offsets = {0, 6};
  c.build_derived();
  return c;
}

// M(u, v) through the frame, for finite differences.
Vec3d surface(const BSplineCurve& c, size_t s, double t, double u) { return c.eval(s, t).c + c.eval(s, t).r * c.radial(s, t, u); }

}  // namespace

TEST_CASE("curve: the frame is continuous across span joints and perpendicular to the tangent") {
  const BSplineCurve c = bent();
  REQUIRE(c.check(c.control_points.data()).empty());
  for (size_t s = 0; s + 1 < c.span_count(); ++s) {
    const Vec3d a = c.radial(s, 1.0, 0.7), b = c.radial(s + 1, 0.0, 0.7);
    CHECK(glm::length(a - b) < 1e-12);
  }
  for (size_t s = 0; s < c.span_count(); ++s)
    for (double t : {0.0, 0.3, 0.51, 1.0}) CHECK(std::abs(glm::dot(c.radial(s, t, 1.3), glm::normalize(c.eval(s, t).c1))) < 1e-12);
}

TEST_CASE("curve: the refined normal is M_u x M_v of the surface (finite differences), with the curvature factor") {
  const BSplineCurve c = bent();
  Pcg32 rng(5);
  double worst = 0.0, embree_like = 0.0;
  for (int i = 0; i < 200; ++i) {
    const size_t s = size_t(rng.next_float() * float(c.span_count())) % c.span_count();
    const double t = 0.05 + 0.9 * rng.next_float(), u = 2 * M_PI * rng.next_float(), h = 1e-6;
    const Vec3d mu = (surface(c, s, t, u + h) - surface(c, s, t, u - h)) / (2 * h);
    const Vec3d mv = (surface(c, s, t + h, u) - surface(c, s, t - h, u)) / (2 * h);
    const Vec3d n_fd = glm::normalize(glm::cross(mu, mv));
    const TubeLocal L = c.local(s, t, u);
    worst = std::max(worst, glm::length(L.n - n_fd));
    // Embree's normal drops (1 - r rho . C'' / |C'|^2): rho - r' T / |C'| normalised.
    const CurveSample cs = c.eval(s, t);
    const Vec3d tu = glm::normalize(cs.c1);
    embree_like = std::max(embree_like, glm::length(glm::normalize(L.rho - cs.r1 / glm::length(cs.c1) * tu) - n_fd));
    CHECK(L.area_density == doctest::Approx(glm::length(glm::cross(mu, mv))).epsilon(1e-6));
  }
  CHECK(worst < 1e-6);
  CHECK(embree_like > 1e-2);  // the factor matters on this curve: the test can tell them apart
}

TEST_CASE("curve: the normal curvature uses the full first fundamental form and does not depend on the frame") {
  const BSplineCurve c = bent();
  Pcg32 rng(9);
  for (int i = 0; i < 100; ++i) {
    const size_t s = size_t(rng.next_float() * float(c.span_count())) % c.span_count();
    const double t = 0.05 + 0.9 * rng.next_float(), u = 2 * M_PI * rng.next_float();
    const CurveSample cs = c.eval(s, t);
    const Vec3d rho = c.radial(s, t, u);
    const TubeLocal a = tube_local(cs, rho), b = tube_local_twisted(cs, rho, 3.0);
    CHECK(std::abs(b.F) > 1e-3);  // the twisted frame has F != 0: the 2x2 solve is exercised
    const double phi = 2 * M_PI * rng.next_float();
    const Vec3d e2 = glm::cross(a.n, a.b), w = std::cos(phi) * a.b + std::sin(phi) * e2;
    CHECK(b.normal_curvature(w) == doctest::Approx(a.normal_curvature(w)).epsilon(1e-9));
    CHECK(b.shape_operator_norm(w) == doctest::Approx(a.shape_operator_norm(w)).epsilon(1e-9));
    // Around the tube: the cross-section circle's curvature 1 / r projected on n (Meusnier).
    CHECK(a.normal_curvature(a.b) == doctest::Approx(glm::dot(a.rho, a.n) / cs.r).epsilon(1e-9));
    // Against a finite difference of the normal along w: dn/ds . w = kappa_n(w). The step goes
    // along w in the curve's own (u, t) parameterisation, whose M_u, M_v come from differences too
    // (its frame may twist slightly; the normal curvature must not care).
    const double h = 1e-6;
    const Vec3d fu = (surface(c, s, t, u + h) - surface(c, s, t, u - h)) / (2 * h);
    const Vec3d fv = (surface(c, s, t + h, u) - surface(c, s, t - h, u)) / (2 * h);
    const double E = glm::dot(fu, fu), F = glm::dot(fu, fv), G = glm::dot(fv, fv);
    const Vec3d wt = w - glm::dot(w, a.n) * a.n;
    const double p = glm::dot(wt, fu), q = glm::dot(wt, fv), det = E * G - F * F;
    const double x0 = (G * p - F * q) / det, x1 = (E * q - F * p) / det;
    const double k = 1e-5;
    const Vec3d np = c.local(s, t + k * x1, u + k * x0).n, nm = c.local(s, t - k * x1, u - k * x0).n;
    CHECK(glm::dot((np - nm) / (2 * k), w) == doctest::Approx(a.normal_curvature(w)).epsilon(1e-4).scale(1e-3));
  }
}

TEST_CASE("curve: silhouette roots make (M - e) . n vanish, closed form and bisection alike") {
  BSplineCurve c = bent();
  BSplineCurve constant = bent();
  for (size_t i = 0; i < constant.point_count(); ++i) constant.control_points[4 * i + 3] = 0.12f;
  constant.build_derived();
  Pcg32 rng(13);
  int found = 0;
  for (const BSplineCurve* g : {&c, &constant})
    for (int i = 0; i < 200; ++i) {
      const size_t s = size_t(rng.next_float() * float(g->span_count())) % g->span_count();
      const double t = rng.next_float();
      const Vec3d e(4 * rng.next_float() - 2, -3.0, 4 * rng.next_float() - 2);
      const SilhouetteEquation q = g->silhouette_equation(s, t, e, false);
      CHECK(q.linear == (g == &constant));
      // The expansion is (M - e) . (M_u x M_v) up to a positive factor: same sign everywhere.
      for (double u = 0; u < 6.28; u += 0.5) {
        const TubeLocal L = g->local(s, t, u);
        const double direct = glm::dot(L.p - e, L.n);
        if (std::abs(direct) > 1e-9) CHECK((q.eval(u) > 0) == (direct > 0));
      }
      for (int side : {-1, 1}) {
        double u;
        if (!BSplineCurve::silhouette_root(q, side, 50, u)) continue;
        ++found;
        const TubeLocal L = g->local(s, t, u);
        CHECK(std::abs(glm::dot(glm::normalize(L.p - e), L.n)) < 1e-9);
      }
    }
  CHECK(found > 700);
}
