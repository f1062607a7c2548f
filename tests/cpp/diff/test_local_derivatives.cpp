// Every local derivative of the interior term against central finite differences (in double), and
// the templated evaluations against the primal float code they mirror.
#include <doctest/doctest.h>

#include <functional>
#include "core/diff/ad/local_derivatives.h"
#include "core/math/rng.h"
#include "core/render/bsdfs/bsdf.h"
#include "core/render/bsdfs/fresnel.h"

using namespace limn;
using ad::Var;

namespace {

// Compares the tape gradient of f at x with central differences of f<double>.
template <typename F>
void check_gradient(F&& f, const std::vector<double>& x, double eps = 1e-6, double tol = 1e-5) {
  ad::Tape::current().clear();
  std::vector<Var> xv;
  for (double v : x) xv.push_back(Var::input(v));
  const Var y = f(xv);
  std::vector<double> adj;
  ad::Tape::current().backward(y.idx, 1.0, adj);
  for (size_t i = 0; i < x.size(); ++i) {
    std::vector<double> xp = x, xm = x;
    xp[i] += eps;
    xm[i] -= eps;
    const double fd = (f(xp) - f(xm)) / (2 * eps);
    const double ad_grad = xv[i].idx >= 0 ? adj[xv[i].idx] : 0.0;
    CAPTURE(i);
    CAPTURE(fd);
    CAPTURE(ad_grad);
    CHECK(std::abs(ad_grad - fd) <= tol * std::max(1.0, std::abs(fd)));
  }
  ad::Tape::current().clear();
}

template <typename T>
ad::V3<T> v3(const std::vector<T>& x, size_t i) { return ad::V3<T>(x[i], x[i + 1], x[i + 2]); }

std::vector<double> random_vector(Pcg32& rng, size_t n, double lo = -1, double hi = 1) {
  std::vector<double> x(n);
  for (double& v : x) v = lo + (hi - lo) * rng.next_float();
  return x;
}

}  // namespace

TEST_CASE("ad: elementary operations against finite differences") {
  auto f = [](const auto& x) {
    using T = std::decay_t<decltype(x[0])>;
    using namespace limn::ad;
    return sin(x[0]) * exp(x[1]) / (T(1.5) + x[2] * x[2]) + sqrt(x[3] * x[3] + T(0.1)) - log(T(2.0) + cos(x[0])) + pow(abs(x[2]) + T(1.0), 2.5) +
           atan(x[1] - x[3]) + max(x[0], x[1]) * min(x[2], x[3]);
  };
  Pcg32 rng(1);
  for (int k = 0; k < 20; ++k) check_gradient(f, random_vector(rng, 4));
  auto g = [](const auto& x) {
    using namespace limn::ad;
    return atan2(x[0], x[1]) + acos(x[2] * 0.9);
  };
  for (int k = 0; k < 20; ++k) check_gradient(g, random_vector(rng, 3));
}

TEST_CASE("geometry: ray-triangle distance and barycentrics w.r.t. vertices and the ray") {
  Pcg32 rng(2);
  for (int k = 0; k < 30; ++k) {
    // x: ray origin (3), direction (3), vertices (9)
    std::vector<double> x = random_vector(rng, 15);
    x[5] = 2.0 + x[5];            // ray mostly along +z
    for (int i = 6; i < 15; i += 3) x[i + 2] += 3.0;  // triangle in front
    auto t_of = [](const auto& x) { return diff::ray_triangle_t(v3(x, 0), v3(x, 3), v3(x, 6), v3(x, 9), v3(x, 12)); };
    check_gradient(t_of, x);
    for (int which = 0; which < 2; ++which) {
      auto b_of = [which](const auto& x) {
        using T = std::decay_t<decltype(x[0])>;
        const auto p = v3(x, 0) + v3(x, 3) * diff::ray_triangle_t(v3(x, 0), v3(x, 3), v3(x, 6), v3(x, 9), v3(x, 12));
        T b1, b2;
        diff::barycentrics(p, v3(x, 6), v3(x, 9), v3(x, 12), b1, b2);
        return which ? b2 : b1;
      };
      check_gradient(b_of, x);
    }
  }
}

TEST_CASE("geometry: ray-sphere distance w.r.t. centre, radius and the ray") {
  Pcg32 rng(3);
  for (int k = 0; k < 30; ++k) {
    std::vector<double> x = {0.1 * rng.next_float(), 0.1 * rng.next_float(), -3.0, 0.05 * rng.next_float(), 0.05 * rng.next_float(), 1.0,
                             0.2 * rng.next_float(), 0.1 * rng.next_float(), 0.3 * rng.next_float(), 0.8 + 0.4 * rng.next_float()};
    for (bool far : {false, true}) {
      auto t_of = [far](const auto& x) { return diff::ray_sphere_t(v3(x, 0), normalize(v3(x, 3)), v3(x, 6), x[9], far); };
      check_gradient(t_of, x);
    }
  }
}

TEST_CASE("fresnel: templated forms equal the primal ones and differentiate correctly") {
  for (double ci : {0.05, 0.3, 0.7, 0.99}) {
    CHECK(fresnel_conductor(ci, 0.0, 1.0) == doctest::Approx(1.0).epsilon(1e-6));
    CHECK(diff::fresnel_dielectric(ci, 1.5) == doctest::Approx(fresnel_dielectric(float(ci), 1.5f).F).epsilon(1e-5));
    CHECK(diff::fresnel_dielectric(-ci, 1.5) == doctest::Approx(fresnel_dielectric(float(-ci), 1.5f).F).epsilon(1e-5));
    check_gradient([](const auto& x) { return fresnel_conductor(x[0], 0.2, 3.9); }, {ci});
    check_gradient([](const auto& x) { return fresnel_conductor(x[0], 1.6, 9.2); }, {ci});
    check_gradient([](const auto& x) { return diff::fresnel_dielectric(x[0], 1.5); }, {ci});
    if (ci > 0.8) check_gradient([](const auto& x) { return diff::fresnel_dielectric(-x[0], 1.5); }, {ci});  // inside, above the critical angle
  }
}

TEST_CASE("bsdfs: templated evaluation equals Bsdf::eval and differentiates in alpha and directions") {
  Microfacet ggx;
  ggx.type = MicrofacetType::GGX;
  ggx.alpha = 0.3f;
  Microfacet beck = ggx;
  beck.type = MicrofacetType::Beckmann;
  const Vec3 eta(0.2f, 0.9f, 1.1f), k(3.9f, 2.4f, 2.1f), tint(1.0f);
  Pcg32 rng(4);
  for (int n = 0; n < 40; ++n) {
    const Vec3 wi = glm::normalize(Vec3(rng.next_float() - 0.5f, rng.next_float() - 0.5f, 0.2f + rng.next_float()));
    const Vec3 wo_r = glm::normalize(Vec3(rng.next_float() - 0.5f, rng.next_float() - 0.5f, 0.2f + rng.next_float()));
    const Vec3 wo_t = Vec3(wo_r.x, wo_r.y, -wo_r.z);
    for (const Microfacet& m : {ggx, beck}) {
      // Values against the primal code.
      const Bsdf cond{"c", RoughConductor{eta, k, tint, m}, false};
      const Bsdf diel{"d", RoughDielectric{1.5f, tint, tint, m}, false};
      const auto ev = diff::eval_rough_conductor<double>(m.type, m.alpha, eta, k, tint, ad::V3<double>(wi), ad::V3<double>(wo_r));
      CHECK(ev.x == doctest::Approx(cond.eval(wi, wo_r, Vec2(0), wi.z > 0).x).epsilon(1e-4));
      for (const Vec3& wo : {wo_r, wo_t}) {
        const auto dv = diff::eval_rough_dielectric<double>(m.type, m.alpha, 1.5, tint, tint, ad::V3<double>(wi), ad::V3<double>(wo));
        CHECK(dv.x == doctest::Approx(diel.eval(wi, wo, Vec2(0), wi.z > 0).x).epsilon(1e-4));
      }
      // Gradients in alpha and both directions (x: alpha, wi (3), wo (3), unnormalised).
      std::vector<double> x = {m.alpha, wi.x, wi.y, wi.z, wo_r.x, wo_r.y, wo_r.z};
      const MicrofacetType type = m.type;
      check_gradient([&](const auto& x) {
        return diff::eval_rough_conductor(type, x[0], eta, k, tint, normalize(v3(x, 1)), normalize(v3(x, 4))).y;
      }, x, 1e-6, 1e-4);
      x[6] = -x[6];
      check_gradient([&](const auto& x) {
        return diff::eval_rough_dielectric(type, x[0], 1.5, tint, tint, normalize(v3(x, 1)), normalize(v3(x, 4))).x;
      }, x, 1e-6, 1e-4);
    }
    check_gradient([&](const auto& x) {
      using T = std::decay_t<decltype(x[0])>;
      return diff::eval_diffuse(ad::V3<T>(x[0], x[0], x[0]), normalize(v3(x, 1)), normalize(v3(x, 4)), true).x;
    }, {0.7, wi.x, wi.y, wi.z, wo_r.x, wo_r.y, wo_r.z});
  }
}

TEST_CASE("frames: the templated frame is orthonormal and matches limn::Frame") {
  Pcg32 rng(5);
  for (int n = 0; n < 100; ++n) {
    const Vec3 nrm = glm::normalize(Vec3(rng.next_float() - 0.5f, rng.next_float() - 0.5f, rng.next_float() - 0.5f));
    const diff::Frame3<double> f{ad::V3<double>(nrm)};
    const Frame g(nrm);
    CHECK(f.s.x == doctest::Approx(g.s.x).epsilon(1e-5));
    CHECK(f.t.y == doctest::Approx(g.t.y).epsilon(1e-5));
    CHECK(std::abs(ad::dot(f.s, f.t)) < 1e-6);
    CHECK(ad::dot(f.s, f.s) == doctest::Approx(1.0));
  }
}
