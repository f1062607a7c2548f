// Exact sphere (not tessellated), registered with Embree as user geometry.
#pragma once
#include "core/geometry/shapes/mesh.h"

namespace limn {

struct Sphere {
  Vec3 center{0.0f};
  float radius = 1.0f;   // > 0

  // Nearest hit with t in (ray.tmin, ray.tmax); quadratic solved in double precision.
  bool intersect(const Ray& ray, float& t_hit) const;
  void fill_interaction(const Vec3& p_hit, SurfaceInteraction& si) const;
  PositionSample sample_position(const Vec2& u) const;
  float area() const { return 4.0f * kPi * radius * radius; }
};

}  // namespace limn
