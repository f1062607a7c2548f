// sdf_from_mesh (core/io/sdf_from_mesh.h): signed distances of a closed mesh against analytic
// answers (a box: exact; a sphere mesh: within its Hausdorff distance to the sphere), the grid's
// layout, and bad input refused with errors that say what is wrong.
#include <doctest/doctest.h>

#include <cmath>
#include <stdexcept>
#include "core/io/sdf_from_mesh.h"
#include "core/render/integrators/render.h"

using namespace limn;

namespace {

struct TestMesh {
  std::vector<double> v;
  std::vector<int64_t> f;
};

// Axis-aligned box [lo, hi], 12 triangles, outward (counter-clockwise seen from outside).
TestMesh box(std::array<double, 3> lo, std::array<double, 3> hi) {
  TestMesh m;
  for (int i = 0; i < 8; ++i) {
    m.v.push_back(i & 1 ? hi[0] : lo[0]);
    m.v.push_back(i & 2 ? hi[1] : lo[1]);
    m.v.push_back(i & 4 ? hi[2] : lo[2]);
  }
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    for (int k : {q[0], q[1], q[2]}) m.f.push_back(k);
    for (int k : {q[0], q[2], q[3]}) m.f.push_back(k);
  }
  return m;
}

// Latitude-longitude sphere of radius r about c, vertices on the sphere, outward.
TestMesh uv_sphere(std::array<double, 3> c, double r, int nu, int nv) {
  TestMesh m;
  auto add = [&](double theta, double phi) {
    m.v.push_back(c[0] + r * std::sin(theta) * std::cos(phi));
    m.v.push_back(c[1] + r * std::sin(theta) * std::sin(phi));
    m.v.push_back(c[2] + r * std::cos(theta));
  };
  add(0, 0);
  for (int i = 1; i < nv; ++i)
    for (int j = 0; j < nu; ++j) add(M_PI * i / nv, 2 * M_PI * j / nu);
  add(M_PI, 0);
  const int south = 1 + (nv - 1) * nu;
  auto ring = [&](int i, int j) { return int64_t(1 + (i - 1) * nu + (j % nu)); };
  for (int j = 0; j < nu; ++j) {
    for (int64_t k : {int64_t(0), ring(1, j), ring(1, j + 1)}) m.f.push_back(k);
    for (int64_t k : {int64_t(south), ring(nv - 1, j + 1), ring(nv - 1, j)}) m.f.push_back(k);
  }
  for (int i = 1; i < nv - 1; ++i)
    for (int j = 0; j < nu; ++j) {
      for (int64_t k : {ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)}) m.f.push_back(k);
      for (int64_t k : {ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)}) m.f.push_back(k);
    }
  return m;
}

std::array<double, 3> sample(const SdfFromMesh& g, int x, int y, int z) {
  return {g.origin[0] + g.voxel * x, g.origin[1] + g.voxel * y, g.origin[2] + g.voxel * z};
}

float value(const SdfFromMesh& g, int x, int y, int z) { return g.values[(size_t(z) * g.ny + y) * g.nx + x]; }

std::string error_of(const TestMesh& m, int resolution, double padding = 0.1) {
  try {
    sdf_from_mesh(m.v, m.f, resolution, padding, "test mesh");
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("sdf_from_mesh: point_triangle_distance matches a dense search over the triangle") {
  const std::array<double, 3> a{0.1, -0.2, 0.3}, b{1.2, 0.1, -0.1}, c{0.3, 0.9, 0.5};
  const std::array<double, 3> points[] = {{0.5, 0.3, 1.0}, {-1, -1, -1}, {2, 0.2, 0}, {0.5, -0.5, 0.1}, {0.4, 0.2, 0.2}};
  for (const auto& p : points) {
    std::array<double, 3> q;
    const double d = point_triangle_distance(p, a, b, c, &q);
    CHECK(std::hypot(q[0] - p[0], q[1] - p[1], q[2] - p[2]) == doctest::Approx(d).epsilon(1e-12));
    double best = 1e30;
    const int n = 400;
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const double u = double(i) / n, w = double(j) / n;
        const double s[3] = {a[0] + u * (b[0] - a[0]) + w * (c[0] - a[0]), a[1] + u * (b[1] - a[1]) + w * (c[1] - a[1]),
                             a[2] + u * (b[2] - a[2]) + w * (c[2] - a[2])};
        best = std::min(best, std::hypot(s[0] - p[0], s[1] - p[1], s[2] - p[2]));
      }
    // The search's own error: half a step of the sampling, 1.3 / 400 along the longest edge.
    CHECK(d <= best + 1e-12);
    CHECK(best - d < 1.3 / n);
  }
}

TEST_CASE("sdf_from_mesh: a box gives the box's exact signed distance and a grid of cubic voxels around it") {
  const std::array<double, 3> lo{-0.3, 0.1, 0.2}, hi{0.5, 0.5, 0.6};
  const TestMesh m = box(lo, hi);
  const SdfFromMesh g = sdf_from_mesh(m.v, m.f, 33, 0.25, "box");
  // Longest side 0.8 padded by 0.2 on each side: 1.2 over 32 voxels.
  CHECK(g.nx == 33);
  CHECK(g.voxel == doctest::Approx(1.2 / 32).epsilon(1e-12));
  CHECK(g.ny == int(std::ceil((0.4 + 0.4) / g.voxel - 1e-9)) + 1);
  CHECK(g.nz == g.ny);
  for (int k = 0; k < 3; ++k) {  // centred on the box
    CHECK(g.origin[k] + 0.5 * g.extent[k] == doctest::Approx(0.5 * (lo[k] + hi[k])).epsilon(1e-12));
    CHECK(g.extent[k] >= hi[k] - lo[k] + 0.4 - 1e-12);
  }
  CHECK(g.sign_disagreements == 0);
  int inside = 0;
  double worst = 0;
  for (int z = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x) {
        const auto p = sample(g, x, y, z);
        double q[3], outside = 0, inner = -1e30;
        for (int k = 0; k < 3; ++k) {
          q[k] = std::abs(p[k] - 0.5 * (lo[k] + hi[k])) - 0.5 * (hi[k] - lo[k]);
          outside += std::max(q[k], 0.0) * std::max(q[k], 0.0);
          inner = std::max(inner, q[k]);
        }
        const double exact = std::sqrt(outside) + std::min(inner, 0.0);
        worst = std::max(worst, std::abs(value(g, x, y, z) - exact));
        inside += value(g, x, y, z) < 0;
      }
  // Float storage of distances up to ~1: 1e-6.
  CHECK(worst < 1e-6);
  CHECK(inside > 0);
}

TEST_CASE("sdf_from_mesh: a sphere mesh is within its chord error of the sphere's distance, signs included") {
  const std::array<double, 3> c{0.2, -0.1, 0.05};
  const double r = 0.7;
  const TestMesh m = uv_sphere(c, r, 48, 24);
  // The mesh lies inside the sphere with its vertices on it, so the two surfaces are within
  // H = r - (the mesh's closest approach to the centre) of each other, and so are their distances.
  double closest = 1e30;
  for (size_t f = 0; f < m.f.size() / 3; ++f) {
    auto vert = [&](int k) {
      const int64_t i = m.f[3 * f + k];
      return std::array<double, 3>{m.v[3 * i], m.v[3 * i + 1], m.v[3 * i + 2]};
    };
    closest = std::min(closest, point_triangle_distance(c, vert(0), vert(1), vert(2)));
  }
  const double H = r - closest;
  REQUIRE(H > 0.0);
  REQUIRE(H < 0.02 * r);
  const SdfFromMesh g = sdf_from_mesh(m.v, m.f, 40, 0.1, "sphere");
  CHECK(g.sign_disagreements == 0);
  double worst = 0;
  int wrong_sign = 0, checked_signs = 0;
  for (int z = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x) {
        const auto p = sample(g, x, y, z);
        const double exact = std::hypot(p[0] - c[0], p[1] - c[1], p[2] - c[2]) - r;
        const float v = value(g, x, y, z);
        worst = std::max(worst, std::abs(v - exact));
        if (std::abs(exact) > H) {
          ++checked_signs;
          wrong_sign += (v < 0) != (exact < 0);
        }
      }
  MESSAGE("sphere: H = " << H << ", worst |sdf - exact| = " << worst);
  CHECK(worst <= H + 1e-6);  // 1e-6: float storage of distances below 1
  CHECK(wrong_sign == 0);
  CHECK(checked_signs > g.nx * g.ny * g.nz / 2);
}

TEST_CASE("sdf_from_mesh: a mesh with a hole, a flipped triangle or a non-manifold edge is refused") {
  TestMesh open = box({0, 0, 0}, {1, 1, 1});
  open.f.resize(open.f.size() - 3);
  CHECK(error_of(open, 8).find("not closed and consistently oriented") != std::string::npos);
  TestMesh flipped = box({0, 0, 0}, {1, 1, 1});
  std::swap(flipped.f[1], flipped.f[2]);
  CHECK(error_of(flipped, 8).find("not closed and consistently oriented") != std::string::npos);
  TestMesh twice = box({0, 0, 0}, {1, 1, 1});
  const TestMesh other = box({0, 0, 0}, {1, 1, 1});
  twice.f.insert(twice.f.end(), other.f.begin(), other.f.end());  // every edge used twice per direction
  const std::string e = error_of(twice, 8);
  CHECK(e.find("non-manifold") != std::string::npos);
  CHECK(e.find("test mesh") != std::string::npos);
  // Two separate closed boxes are fine (the sign is parity).
  TestMesh two = box({0, 0, 0}, {1, 1, 1});
  const TestMesh b2 = box({2, 0, 0}, {3, 1, 1});
  for (int64_t i : b2.f) two.f.push_back(i + 8);
  two.v.insert(two.v.end(), b2.v.begin(), b2.v.end());
  CHECK(error_of(two, 8) == "");
}

TEST_CASE("sdf_from_mesh: bad input is refused naming the value") {
  const TestMesh b = box({0, 0, 0}, {1, 1, 1});
  CHECK(error_of(TestMesh{}, 8).find("no triangles") != std::string::npos);
  TestMesh nan = b;
  nan.v[7] = std::nan("");
  CHECK(error_of(nan, 8).find("vertex 2 has a non-finite coordinate") != std::string::npos);
  TestMesh inf = b;
  inf.v[0] = INFINITY;
  CHECK(error_of(inf, 8).find("vertex 0 has a non-finite") != std::string::npos);
  CHECK(error_of(b, 1).find("resolution must be within [2, 1024]") != std::string::npos);
  CHECK(error_of(b, 1).find("got 1)") != std::string::npos);
  CHECK(error_of(b, 100000).find("got 100000") != std::string::npos);
  CHECK(error_of(b, 8, -0.1).find("padding") != std::string::npos);
  CHECK(error_of(b, 8, NAN).find("padding") != std::string::npos);
  TestMesh out_of_range = b;
  out_of_range.f[4] = 8;
  CHECK(error_of(out_of_range, 8).find("triangle 1 refers to vertex 8, outside [0, 8)") != std::string::npos);
  TestMesh negative = b;
  negative.f[0] = -1;
  CHECK(error_of(negative, 8).find("refers to vertex -1") != std::string::npos);
  TestMesh repeated = b;
  repeated.f[1] = repeated.f[0];
  CHECK(error_of(repeated, 8).find("repeats a vertex") != std::string::npos);
  TestMesh ragged = b;
  ragged.f.pop_back();
  CHECK(error_of(ragged, 8).find("not a multiple of 3") != std::string::npos);
  // 1024 samples along the longest side of a cube padded by 10 sides: 1024^3 > 2^28 samples.
  CHECK(error_of(box({0, 0, 0}, {1, 1, 1}), 1024, 10.0).find("too large") != std::string::npos);
}

TEST_CASE("sdf_from_mesh: a progress callback that returns false cancels") {
  const TestMesh b = box({0, 0, 0}, {1, 1, 1});
  int calls = 0;
  CHECK_THROWS_AS(sdf_from_mesh(b.v, b.f, 16, 0.1, "box", [&](float) { return ++calls < 3; }), RenderCancelled);
  CHECK(calls == 3);
  float last = 0;
  sdf_from_mesh(b.v, b.f, 16, 0.1, "box", [&](float f) { last = f; return true; });
  CHECK(last == 1.0f);
}
