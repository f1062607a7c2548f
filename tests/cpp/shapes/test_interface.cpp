// The shape interface's compile-time checks reject a kind that lacks an operation. Every
// alternative of ShapeGeometry must pass ShapeKind (core/geometry/shapes/shape.h) and
// DifferentiableShapeKind (core/diff/shapes/all.h, static_asserts), so such a kind does not compile.
#include <doctest/doctest.h>

#include "core/diff/shapes/all.h"

using namespace limn;

namespace {

// Sphere with one operation hidden: no surface area.
struct WithoutArea : Sphere {
 private:
  using Sphere::area;
};
// A kind that says it can emit but cannot sample points.
struct EmitsWithoutSampling : Heightfield {
  static constexpr bool can_emit = true;
};
// Derivative groups: complete, one group explicitly unsupported, and one group missing an operation.
struct AllGroups : Sphere {};
struct NoBoundaryTerms : Sphere {};
struct BoundaryWithoutInverse : Sphere {};

}  // namespace

namespace limn {
template <> struct SurfaceDiff<AllGroups> : SurfaceDiff<Sphere> {};
template <> struct BoundarySegments<AllGroups> : BoundarySegments<Sphere> {};
template <> struct CameraSilhouettes<AllGroups> : CameraSilhouettes<Sphere> {};

template <> struct SurfaceDiff<NoBoundaryTerms> : SurfaceDiff<Sphere> {};
template <> struct BoundarySegments<NoBoundaryTerms> : Unsupported {
  static constexpr const char* reason = "test";
};
template <> struct CameraSilhouettes<NoBoundaryTerms> : Unsupported {
  static constexpr const char* reason = "test";
};

template <> struct SurfaceDiff<BoundaryWithoutInverse> : SurfaceDiff<Sphere> {};
// Every operation of the sphere's group except invert.
template <> struct BoundarySegments<BoundaryWithoutInverse> {
  using S = BoundarySegments<Sphere>;
  static constexpr const char* segment_name = "test";
  static constexpr auto append = S::append;
  static constexpr auto sample = S::sample;
  static constexpr auto sample_delta = S::sample_delta;
  static constexpr auto attached_point = S::attached_point;
  static constexpr auto projector = S::projector;
};
template <> struct CameraSilhouettes<BoundaryWithoutInverse> : CameraSilhouettes<Sphere> {};
}  // namespace limn

static_assert(ShapeKind<Mesh> && ShapeKind<Sphere> && ShapeKind<Heightfield>);
static_assert(!ShapeKind<WithoutArea>, "a kind without area() must not pass");
static_assert(!ShapeKind<EmitsWithoutSampling>, "a kind that can emit must sample positions");
static_assert(DifferentiableShapeKind<Mesh> && DifferentiableShapeKind<Sphere> && DifferentiableShapeKind<Heightfield>);
static_assert(DifferentiableShapeKind<AllGroups>);
static_assert(DifferentiableShapeKind<NoBoundaryTerms>, "a group may be unsupported, explicitly");
static_assert(!DifferentiableShapeKind<BoundaryWithoutInverse>, "a supported group must have every operation");

TEST_CASE("shape interface: a kind that lacks an operation fails the compile-time checks") {
  // The static_asserts above are the test; this case records that the file compiled.
  CHECK(!ShapeKind<WithoutArea>);
  CHECK(!DifferentiableShapeKind<BoundaryWithoutInverse>);
  CHECK(is_unsupported<BoundarySegments<Heightfield>>);
}
