#include "core/io/scene/shapes.h"

namespace limn::io_detail {

// Mitsuba's disk: the unit disk in the local xy plane facing +z, placed by to_world (a rotation,
// uniform scale and translation: the scale is the radius).
ShapeGeometry load_disk(const Props& p, const std::string&, const Transform& to_world) {
  Disk d;
  float scale = 1.0f;
  if (p.has("to_world")) scale = float(check_similarity(p, to_world));
  if (!(scale > 0.0f) || !std::isfinite(scale)) p.fail("to_world must scale by a finite factor > 0 (got " + std::to_string(scale) + ")");
  d.center = to_world.point(Vec3(0.0f));
  d.n = glm::normalize(to_world.vector(Vec3(0, 0, 1)));  // faces to_world's +z
  d.s = glm::normalize(to_world.vector(Vec3(1, 0, 0)));
  d.t = glm::cross(d.n, d.s);                            // right-handed also under a reflection
  d.radius = scale;
  return d;
}

}  // namespace limn::io_detail
