// The SDF grid's ray/voxel intersection (core/geometry/shapes/sdfgrid.cpp): the first root of the
// cubic along a ray (Marmitt et al. 2004 splitting), rays that start inside a voxel, tmin past a
// root, a root exactly at tmin, a tangent (double) root, and the tight per-voxel bounds.
#include <doctest/doctest.h>

#include "core/geometry/shapes/sdfgrid.h"

using namespace limn;

namespace {

// A 2 x 2 x 2 grid (one voxel) with the given corner values (corner q at (q & 1, q >> 1 & 1, q >> 2 & 1)).
SdfGrid one_voxel(const double c[8]) {
  SdfGrid g;
  g.nx = g.ny = g.nz = 2;
  g.values.resize(8);
  for (int q = 0; q < 8; ++q) g.values[g.sample_index(q & 1, (q >> 1) & 1, (q >> 2) & 1)] = float(c[q]);
  g.world_from_local = Transform();
  g.build_derived();
  return g;
}

}  // namespace

TEST_CASE("sdfgrid: first_cubic_root finds the first of several roots, tangent roots and none") {
  double t;
  // (t - 0.2)(t - 0.5)(t - 0.9): the first root in each window.
  const double c0 = -0.09, c1 = 0.1 + 0.18 + 0.45, c2 = -1.6, c3 = 1.0;
  REQUIRE(first_cubic_root(c0, c1, c2, c3, 0.0, 1.0, t));
  CHECK(t == doctest::Approx(0.2).epsilon(1e-12));
  REQUIRE(first_cubic_root(c0, c1, c2, c3, 0.3, 1.0, t));
  CHECK(t == doctest::Approx(0.5).epsilon(1e-12));
  REQUIRE(first_cubic_root(c0, c1, c2, c3, 0.6, 1.0, t));
  CHECK(t == doctest::Approx(0.9).epsilon(1e-12));
  CHECK_FALSE(first_cubic_root(c0, c1, c2, c3, 0.91, 1.0, t));
  // (t - 0.5)^2 (t + 1) = t^3 - 0.75 t + 0.25: a tangent (double) root. Past it nothing; over it at
  // most the touching point itself (a ray exactly tangent to the surface), never another t.
  CHECK_FALSE(first_cubic_root(0.25, -0.75, 0.0, 1.0, 0.6, 1.0, t));
  if (first_cubic_root(0.25, -0.75, 0.0, 1.0, 0.0, 1.0, t)) CHECK(t == doctest::Approx(0.5).epsilon(1e-12));
  // All zero: the line lies in the zero set, no crossing.
  CHECK_FALSE(first_cubic_root(0.0, 0.0, 0.0, 0.0, 0.0, 1.0, t));
}

TEST_CASE("sdfgrid: rays from inside a voxel, tmin past a root and a root at tmin") {
  // f = z - 0.5 (a plane across the voxel), and f = x + y + z - 1.5 through the voxel's centre.
  const double plane[8] = {-0.5, -0.5, -0.5, -0.5, 0.5, 0.5, 0.5, 0.5};
  const SdfGrid g = one_voxel(plane);
  REQUIRE(g.prims.size() == 1);
  double t;
  // From inside the voxel, below the plane, going up: t = 0.3.
  REQUIRE(g.intersect_voxel(0, Vec3d(0.3, 0.4, 0.2), Vec3d(0, 0, 1), 0.0, 10.0, t));
  CHECK(t == doctest::Approx(0.3).epsilon(1e-12));
  // Starting on the surface (a spawned ray): the root at tmin is not a hit; nothing else ahead.
  CHECK_FALSE(g.intersect_voxel(0, Vec3d(0.3, 0.4, 0.5), Vec3d(0, 0, 1), 0.0, 10.0, t));
  // tmin past the root: no hit; tmax before it: no hit.
  CHECK_FALSE(g.intersect_voxel(0, Vec3d(0.3, 0.4, -1.0), Vec3d(0, 0, 1), 1.6, 10.0, t));
  CHECK_FALSE(g.intersect_voxel(0, Vec3d(0.3, 0.4, -1.0), Vec3d(0, 0, 1), 0.0, 1.4, t));
  REQUIRE(g.intersect_voxel(0, Vec3d(0.3, 0.4, -1.0), Vec3d(0, 0, 1), 1.4, 10.0, t));
  CHECK(t == doctest::Approx(1.5).epsilon(1e-12));
  // A ray in the plane z = 0.5 (grazing along the zero set): no crossing, and no NaN.
  CHECK_FALSE(g.intersect_voxel(0, Vec3d(-1.0, 0.4, 0.5), Vec3d(1, 0, 0), 0.0, 10.0, t));

  // A saddle f = (x - 0.5)(y - 0.5) - 1/64 (corner values exact in float): two sheets; a ray from inside between them meets the
  // nearer one first, and with tmin past it the next.
  double saddle[8];
  for (int q = 0; q < 8; ++q) saddle[q] = ((q & 1) - 0.5) * (((q >> 1) & 1) - 0.5) - 1.0 / 64.0;
  const SdfGrid s = one_voxel(saddle);
  // Along the diagonal x = y = u: f = (u - 0.5)^2 - 1/64, roots u = 0.375 and 0.625.
  const Vec3d o(0.0, 0.0, 0.5), d = glm::normalize(Vec3d(1, 1, 0));
  REQUIRE(s.intersect_voxel(0, o, d, 0.0, 10.0, t));
  CHECK(t == doctest::Approx(0.375 * std::sqrt(2.0)).epsilon(1e-12));
  REQUIRE(s.intersect_voxel(0, o, d, 0.5 * std::sqrt(2.0), 10.0, t));
  CHECK(t == doctest::Approx(0.625 * std::sqrt(2.0)).epsilon(1e-12));
}

TEST_CASE("sdfgrid: voxel bounds hold the patch and are tighter than the voxel") {
  // A corner cut: only the corner at the origin is inside.
  const double corner[8] = {-0.1, 0.9, 0.9, 1.9, 0.9, 1.9, 1.9, 2.9};
  const SdfGrid g = one_voxel(corner);
  REQUIRE(g.prims.size() == 1);
  const SdfGrid::Prim& p = g.prims[0];
  for (int a = 0; a < 3; ++a) {
    CHECK(p.lo[a] == 0.0f);
    CHECK(p.hi[a] <= 0.25f);  // the surface stays within 0.1 / 0.9 of the corner: one sub-cell of four
  }
  // A grid with no zero crossing, and one that is zero everywhere, have no primitives.
  const double positive[8] = {1, 1, 1, 1, 1, 1, 1, 1}, zero[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  CHECK(one_voxel(positive).prims.empty());
  CHECK(one_voxel(zero).prims.empty());
}
