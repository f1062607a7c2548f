// Ray-shape intersection: analytic hits, no self re-hit from a hit point at several scales,
// Embree's error callback, transforms.
#include <doctest/doctest.h>

#include "tests/cpp/test_util.h"

#include "core/render/accel.h"
#include "core/geometry/transform.h"
#include "core/math/rng.h"
#include "core/math/warp.h"

using namespace limn;

namespace {
Shape sphere_shape(Vec3 c, float r) {
  Shape s;
  s.id = "ball";
  s.geometry = Sphere{c, r};
  return s;
}
Shape quad_shape(float half, float z) {
  Mesh m;
  m.positions = {-half, -half, z, half, -half, z, half, half, z, -half, half, z};
  m.indices = {0, 1, 2, 0, 2, 3};
  m.face_normals = true;
  m.update_derived();
  Shape s;
  s.id = "quad";
  s.geometry = m;
  return s;
}
}  // namespace

TEST_CASE("sphere: analytic hits") {
  const Sphere s{Vec3(1, 2, 3), 0.5f};
  float t;
  REQUIRE(s.intersect(Ray{Vec3(1, 2, 0), Vec3(0, 0, 1)}, t));
  CHECK(t == doctest::Approx(2.5f));                      // front of the sphere, 3 - 0.5
  REQUIRE(s.intersect(Ray{Vec3(1, 2, 3), Vec3(0, 0, 1)}, t));
  CHECK(t == doctest::Approx(0.5f));                      // from the centre: the radius
  CHECK_FALSE(s.intersect(Ray{Vec3(1, 2.6f, 0), Vec3(0, 0, 1)}, t));  // passes beside it
  CHECK_FALSE(s.intersect(Ray{Vec3(1, 2, 0), Vec3(0, 0, -1)}, t));    // pointing away
  CHECK_FALSE(s.intersect(Ray{Vec3(1, 2, 0), Vec3(0, 0, 1), 0.0f, 2.0f}, t));  // beyond tmax
  // A far-away ray keeps precision: 1e4 units away, radius 1e-2.
  const Sphere small{Vec3(0.0f), 1e-2f};
  REQUIRE(small.intersect(Ray{Vec3(0, 0, -1e4f), Vec3(0, 0, 1)}, t));
  CHECK(t == doctest::Approx(1e4f - 1e-2f).epsilon(1e-6));
}

TEST_CASE("accel: triangle and sphere hits through Embree") {
  std::vector<Shape> shapes = {quad_shape(1.0f, 0.0f), sphere_shape(Vec3(0, 0, 2), 0.5f)};
  Accel accel(shapes);
  SurfaceInteraction si;
  REQUIRE(accel.intersect(Ray{Vec3(0.25f, -0.5f, -1), Vec3(0, 0, 1)}, si));  // will hit the quad at t = 1
  CHECK(si.shape == 0);
  CHECK(si.t == doctest::Approx(1.0f));
  CHECK(si.p.x == doctest::Approx(0.25f));
  CHECK(si.p.y == doctest::Approx(-0.5f));
  CHECK(si.ng.z == doctest::Approx(1.0f));
  REQUIRE(accel.intersect(Ray{Vec3(0, 0, 5), Vec3(0, 0, -1)}, si));  // hits the sphere top at t = 2.5
  CHECK(si.shape == 1);
  CHECK(si.t == doctest::Approx(2.5f));
  CHECK(si.ng.z == doctest::Approx(1.0f));
  CHECK(accel.occluded(Ray{Vec3(0, 0, 5), Vec3(0, 0, -1)}));
  CHECK_FALSE(accel.occluded(Ray{Vec3(0, 0, 5), Vec3(0, 0, -1), 0.0f, 2.0f}));
  CHECK_FALSE(accel.intersect(Ray{Vec3(3, 3, -1), Vec3(0, 0, 1)}, si));

  // Moving a shape and refitting.
  test::geometry<Sphere>(shapes, 1).center = Vec3(0, 0, 3);
  accel.shape_changed(1);
  accel.commit();
  REQUIRE(accel.intersect(Ray{Vec3(0, 0, 5), Vec3(0, 0, -1)}, si));
  CHECK(si.t == doctest::Approx(1.5f));
  Mesh& floor = test::geometry<Mesh>(shapes, 0);
  floor.positions[2] = floor.positions[5] = floor.positions[8] = floor.positions[11] = -1.0f;
  floor.update_derived();
  accel.shape_changed(0);
  accel.commit();
  REQUIRE(accel.intersect(Ray{Vec3(0.25f, -0.5f, -3), Vec3(0, 0, 1)}, si));
  CHECK(si.t == doctest::Approx(2.0f));
}

TEST_CASE("no self re-hit from a hit point, at scales 1e-4 to 1e4") {
  for (float scale : {1e-4f, 1.0f, 1e4f}) {
    CAPTURE(scale);
    const Vec3 offset = Vec3(3.0f, -2.0f, 1.0f) * scale;  // away from the origin: absolute error matters
    // The quad lies exactly in z = 0, where the hit point's z is computed without rounding error.
    std::vector<Shape> shapes = {sphere_shape(offset, scale), quad_shape(8.0f * scale, 0.0f)};
    Accel accel(shapes);
    Pcg32 rng(17);
    int rehits = 0, inward_bad = 0, trials = 0;
    for (int i = 0; i < 20000; ++i) {
      const Vec3 dir = warp::square_to_uniform_sphere(rng.next_2d());
      const Vec3 origin = offset + dir * (5.0f * scale);
      SurfaceInteraction si;
      if (!accel.intersect(Ray{origin, -dir}, si)) continue;
      ++trials;
      // Leave into the hemisphere of the normal: a convex surface cannot be hit again.
      Vec3 out = warp::square_to_uniform_hemisphere(rng.next_2d());
      out = Frame(si.ng).to_world(out);
      SurfaceInteraction si2;
      if (accel.intersect(spawn_ray(si, out), si2) && si2.shape == si.shape) ++rehits;
      // Enter the sphere: the next hit is the far side, not the starting point.
      if (si.shape == 0) {
        const Vec3 in = -Frame(si.ng).to_world(warp::square_to_cosine_hemisphere(rng.next_2d()));
        if (!accel.intersect(spawn_ray(si, in), si2) || si2.t < 1e-3f * scale) ++inward_bad;
      }
    }
    CHECK(trials > 1000);
    CHECK(rehits == 0);
    CHECK(inward_bad == 0);
  }
}

TEST_CASE("Embree errors reach our callback and become exceptions at the edge") {
  RTCDevice device = EmbreeDevice::get();
  const size_t before = EmbreeDevice::error_count();
  RTCGeometry g = rtcNewGeometry(device, RTCGeometryType(12345));  // not a geometry type: Embree reports it
  CHECK(g == nullptr);
  CHECK(EmbreeDevice::error_count() == before + 1);
  CHECK(EmbreeDevice::last_error().find("Embree error") != std::string::npos);
  CHECK_THROWS_WITH_AS(EmbreeDevice::check("test"), doctest::Contains("test: Embree error"), std::runtime_error);
  CHECK_NOTHROW(EmbreeDevice::check("again"));  // reported once
}

TEST_CASE("transforms: composition order, inverses, look_at convention") {
  const Transform t = Transform::translate(Vec3d(1, 2, 3)) * Transform::rotate(Vec3d(0, 0, 1), 90.0);
  const Vec3 p = t.point(Vec3(1, 0, 0));  // rotate first: (0, 1, 0), then translate
  CHECK(p.x == doctest::Approx(1.0f));
  CHECK(p.y == doctest::Approx(3.0f));
  CHECK(p.z == doctest::Approx(3.0f));
  const Vec3 back = t.inverse().point(p);
  CHECK(back.x == doctest::Approx(1.0f));
  CHECK(std::abs(back.y) < 1e-6f);
  const Transform la = Transform::look_at(Vec3d(0, -5, 0), Vec3d(0, 0, 0), Vec3d(0, 0, 1));
  const Vec3 fwd = la.vector(Vec3(0, 0, 1)), up = la.vector(Vec3(0, 1, 0)), left = la.vector(Vec3(1, 0, 0));
  CHECK(fwd.y == doctest::Approx(1.0f));
  CHECK(up.z == doctest::Approx(1.0f));
  CHECK(left.x == doctest::Approx(-1.0f));  // +x of the camera points to the image's left
  const Transform s = Transform::scale(Vec3d(2, 2, 2));
  const Vec3 n = s.normal(Vec3(0, 0, 1));
  CHECK(n.z == doctest::Approx(1.0f));
  CHECK_THROWS_AS(Transform(Mat4d(0.0)), std::invalid_argument);
  CHECK_THROWS_AS(Transform::scale(Vec3d(1, 0, 1)), std::invalid_argument);
  CHECK_THROWS_AS(Transform::look_at(Vec3d(0), Vec3d(0, 0, 1), Vec3d(0, 0, 1)), std::invalid_argument);
}

TEST_CASE("accel: rays Embree cannot trace miss and are counted, never reach Embree") {
  // Embree asserts on NaN or components beyond FLT_LARGE (1.844e18) in origin or direction.
  std::vector<Shape> shapes{quad_shape(1.0f, 0.0f)};
  Accel accel(shapes);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  SurfaceInteraction si;
  REQUIRE(accel.intersect(Ray{Vec3(0, 0, 1), Vec3(0, 0, -1)}, si));  // an ordinary ray hits
  CHECK(accel.invalid_rays() == 0);
  const Ray bad[] = {Ray{Vec3(1e38f, 0, 1), Vec3(0, 0, -1)}, Ray{Vec3(0, 0, 1), Vec3(nan, 0, -1)},
                     Ray{Vec3(0, 0, 1), Vec3(0, 0, -1), nan, kInfinity}, Ray{Vec3(0, 0, kInfinity), Vec3(0, 0, -1)},
                     Ray{Vec3(0, 0, 1), Vec3(0, 0, -2e18f)}};
  for (const Ray& r : bad) {
    CHECK(!accel.intersect(r, si));
    CHECK(!accel.occluded(r));
  }
  CHECK(accel.invalid_rays() == 2 * std::size(bad));
  // Up to the limit rays are traced as usual.
  CHECK(accel.intersect(Ray{Vec3(0.5f, 0.5f, 1e18f), Vec3(0, 0, -1)}, si));
  CHECK(accel.invalid_rays() == 2 * std::size(bad));
}
