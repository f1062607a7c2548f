// The shape interface, geometry half: the closed set of shape kinds and what every kind implements.
// The derivative half (attaching points, boundary segments, projections, camera silhouettes) is in
// core/diff/shapes/interface.h. docs/architecture.md, "Adding a shape kind", lists both.
//
// Dispatch is std::visit over ShapeGeometry, never a test of which kind a shape is: a kind missing
// an operation fails the ShapeKind check below at compile time. A kind that cannot do something says
// so with a constant (can_emit), and the call refuses with the shape named.
#pragma once
#include <concepts>
#include <stdexcept>
#include <string>
#include <variant>
#include "core/geometry/parameter.h"
#include "core/geometry/shapes/curve.h"
#include "core/geometry/shapes/disk.h"
#include "core/geometry/shapes/heightfield/heightfield.h"
#include "core/geometry/shapes/mesh.h"
#include "core/geometry/shapes/sdfgrid.h"
#include "core/geometry/shapes/sphere.h"

namespace limn {

using ShapeGeometry = std::variant<Mesh, Sphere, Heightfield, Disk, SdfGrid, BSplineCurve>;

// What a shape kind G implements (see Mesh for the documentation of each operation).
template <typename G>
concept ShapeKind = requires(G& g, const G& cg, RTCDevice device, RTCGeometry geometry, const Ray& ray, SurfaceInteraction& si,
                             const std::string& id, std::vector<Parameter>& params, const Parameter& p, std::vector<float>& values,
                             Vec3& v) {
  { G::kind_name } -> std::convertible_to<const char*>;
  g.build_derived();  // derived state (normals, adjacency, mipmaps) once after loading
  // Embree registration and intersection.
  { cg.create_embree_geometry(device) } -> std::same_as<RTCGeometry>;
  cg.update_embree_geometry(geometry);
  cg.fill_hit(ray, 1.0f, 0u, Vec2(0.0f), si);
  // Surface measure, and position sampling where the kind can be an area emitter.
  { cg.area() } -> std::convertible_to<float>;
  { G::can_emit } -> std::convertible_to<bool>;
  requires !G::can_emit || requires(const Vec2& u) { { cg.sample_position(u, 0.0f) } -> std::same_as<PositionSample>; };
  // Parameter descriptors: listed, validated, applied; the shared translation moves the surface.
  g.list_parameters(id, 0, params);
  cg.validate_parameter(p, id);
  g.apply_parameter(p);
  g.translate(v);
  cg.bounds(v, v);  // world-space bounding box
  cg.geometry_state(values, v, v);
};

template <typename... Kinds>
constexpr bool all_shape_kinds(const std::variant<Kinds...>*) {
  return (ShapeKind<Kinds> && ...);
}
static_assert(all_shape_kinds(static_cast<const ShapeGeometry*>(nullptr)), "every alternative of ShapeGeometry must implement ShapeKind");

struct Shape {
  std::string id;          // unique name in the scene (the dictionary key in the scene description)
  std::string type;        // scene-format type it was created from: obj, ply, mesh, rectangle, cube, sphere, heightfield, disk, sdfgrid, bsplinecurve
  ShapeGeometry geometry;
  int bsdf = -1;           // index into Scene::bsdfs
  int emitter = -1;        // index into Scene::emitters (an area emitter), or -1
  Vec3 translation{0.0f};  // "<id>.to_world.translation": rigid motion applied on top of the geometry

  template <typename F>
  decltype(auto) visit(F&& f) const { return std::visit(std::forward<F>(f), geometry); }
  template <typename F>
  decltype(auto) visit(F&& f) { return std::visit(std::forward<F>(f), geometry); }

  const char* kind_name() const {
    return visit([](const auto& g) { return std::decay_t<decltype(g)>::kind_name; });
  }
  float surface_area() const {
    return visit([](const auto& g) { return float(g.area()); });
  }
  // Uniform point on the surface (pdf_area = 1 / area), for area emitters.
  PositionSample sample_position(const Vec2& u, float u_extra) const {
    return visit([&](const auto& g) -> PositionSample {
      using G = std::decay_t<decltype(g)>;
      if constexpr (G::can_emit) return g.sample_position(u, u_extra);
      else throw std::logic_error("shape '" + id + "': a " + G::kind_name + " cannot emit, so nothing samples points on it");
    });
  }
};

}  // namespace limn
