// Exact sphere (not tessellated), registered with Embree as user geometry.
#pragma once
#include <embree3/rtcore.h>
#include "core/geometry/shapes/mesh.h"

namespace limn {

struct Sphere {
  static constexpr const char* kind_name = "sphere";
  static constexpr bool can_emit = true;

  Vec3 center{0.0f};
  float radius = 1.0f;   // > 0

  // Nearest hit with t in (ray.tmin, ray.tmax); quadratic solved in double precision.
  bool intersect(const Ray& ray, float& t_hit) const;
  void fill_interaction(const Vec3& p_hit, SurfaceInteraction& si) const;

  // ---- the shape interface (core/geometry/shapes/shape.h) ----
  void build_derived() {}
  RTCGeometry create_embree_geometry(RTCDevice device) const;
  void update_embree_geometry(RTCGeometry) const {}  // the bounds callback reads the current centre and radius
  void fill_hit(const Ray& ray, float t, unsigned, const Vec2&, SurfaceInteraction& si) const { fill_interaction(ray(t), si); }
  float area() const { return 4.0f * kPi * radius * radius; }
  PositionSample sample_position(const Vec2& u, float u_extra) const;  // uniform over the sphere (u_extra unused)
  // "<id>.center" (3) and "<id>.radius" (scalar).
  void list_parameters(const std::string& id, int index, std::vector<Parameter>& out);
  void validate_parameter(const Parameter& p, const std::string& where) const;
  void apply_parameter(const Parameter&) {}
  void translate(const Vec3& delta) { center += delta; }
  void bounds(Vec3& lo, Vec3& hi) const {
    lo = center - Vec3(radius);
    hi = center + Vec3(radius);
  }
  void geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const;
};

}  // namespace limn
