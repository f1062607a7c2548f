#include "core/io/scene/shapes.h"

#include <cfloat>
#include "core/io/formats/files.h"

namespace limn::io_detail {

ShapeGeometry load_sphere(const Props& p, const std::string& type, const Transform& to_world) {
  Sphere s;
  s.center = p.vec3("center", Vec3(0.0f));
  s.radius = p.number("radius", 1.0f);
  if (!(s.radius > 0.0f)) p.fail("radius must be > 0 (got " + std::to_string(s.radius) + ")");
  double radius = s.radius;  // in double, to check what the float results will be
  Vec3d center(s.center);
  if (p.has("to_world")) {
    const double scale = check_similarity(p, to_world);
    center = Vec3d(to_world.matrix() * glm::dvec4(center, 1.0));
    radius *= scale;
    s.center = to_world.point(s.center);
    s.radius *= float(scale);
    if (!(s.radius >= kMinRadius && s.radius <= kMaxRadius)) s.radius = float(radius);  // float(scale) alone over- or underflowed
  }
  // The intersection and the area (4 pi r^2) work with r^2 in float.
  if (!(radius >= kMinRadius && radius <= kMaxRadius))
    p.fail("'radius' " + number_text(p.number("radius", 1.0f)) + (p.has("to_world") ? " scaled by 'to_world'" : "") + " is " + number_text(radius) +
           ", outside [" + number_text(kMinRadius) + ", " + number_text(kMaxRadius) + "] (its square must be a normal float)");
  for (int a = 0; a < 3; ++a)
    if (!(std::abs(center[a]) + radius <= kMaxCoordinate))
      p.fail("'center' " + (p.has("to_world") ? std::string("moved by 'to_world' ") : std::string()) + "is [" + number_text(center.x) + ", " +
             number_text(center.y) + ", " + number_text(center.z) + "]: the sphere (radius " + number_text(radius) + ") reaches beyond " +
             number_text(kMaxCoordinate) + ", the largest world coordinate limn traces rays at");
  return s;
}

}  // namespace limn::io_detail
