// Exact flat disk (Mitsuba's `disk`: the unit disk in the local xy plane, facing local +z, placed
// by to_world), registered with Embree as user geometry. One-sided for emission, two-sided for
// intersection, like limn's rectangles.
#pragma once
#include <embree3/rtcore.h>
#include "core/geometry/shapes/mesh.h"

namespace limn {

struct Disk {
  static constexpr const char* kind_name = "disk";
  static constexpr bool can_emit = true;

  Vec3 center{0.0f};
  Vec3 s{1, 0, 0}, t{0, 1, 0}, n{0, 0, 1};  // orthonormal frame: the local x, y and z axes (fixed)
  float radius = 1.0f;                      // > 0

  Vec3 at(const Vec2& local) const { return center + radius * (local.x * s + local.y * t); }  // local: unit-disk coordinates
  // Nearest hit with t in (ray.tmin, ray.tmax), in double precision.
  bool intersect(const Ray& ray, float& t_hit) const;
  // Surface record at unit-disk coordinates `local` (its material coordinates, kept in si.bary).
  void fill_interaction(const Vec2& local, SurfaceInteraction& si) const;

  // ---- the shape interface (core/geometry/shapes/shape.h) ----
  void build_derived() {}
  RTCGeometry create_embree_geometry(RTCDevice device) const;
  void update_embree_geometry(RTCGeometry) const {}  // the bounds callback reads the current centre and radius
  void fill_hit(const Ray& ray, float t_hit, unsigned, const Vec2&, SurfaceInteraction& si) const;
  float area() const { return kPi * radius * radius; }
  PositionSample sample_position(const Vec2& u, float u_extra) const;  // uniform over the disk (u_extra unused)
  // "<id>.radius" (scalar).
  void list_parameters(const std::string& id, int index, std::vector<Parameter>& out);
  void validate_parameter(const Parameter& p, const std::string& where) const;
  void apply_parameter(const Parameter&) {}
  void translate(const Vec3& delta) { center += delta; }
  void bounds(Vec3& lo, Vec3& hi) const;
  void geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const;
};

}  // namespace limn
