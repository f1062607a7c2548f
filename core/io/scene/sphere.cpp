#include "core/io/scene/shapes.h"

namespace limn::io_detail {

ShapeGeometry load_sphere(const Props& p, const std::string& type, const Transform& to_world) {
  Sphere s;
  s.center = p.vec3("center", Vec3(0.0f));
  s.radius = p.number("radius", 1.0f);
  if (!(s.radius > 0.0f)) p.fail("radius must be > 0 (got " + std::to_string(s.radius) + ")");
  if (p.has("to_world")) {
    float scale;
    check_similarity(p, to_world, scale);
    s.center = to_world.point(s.center);
    s.radius *= scale;
  }
  return s;
}

}  // namespace limn::io_detail
