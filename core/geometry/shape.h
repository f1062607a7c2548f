// The closed set of shapes. A new shape adds an alternative to ShapeGeometry; std::visit then lists
// every operation it still lacks at compile time.
#pragma once
#include <string>
#include <variant>
#include "core/geometry/shapes/mesh.h"
#include "core/geometry/shapes/sphere.h"
#include "core/heightfield/heightfield.h"
#include <stdexcept>

namespace limn {

using ShapeGeometry = std::variant<Mesh, Sphere, Heightfield>;

struct Shape {
  std::string id;          // unique name in the scene (the dictionary key in the scene description)
  std::string type;        // scene-format type it was created from: obj, ply, mesh, rectangle, cube, sphere, heightfield
  ShapeGeometry geometry;
  int bsdf = -1;           // index into Scene::bsdfs
  int emitter = -1;        // index into Scene::emitters (an area emitter), or -1
  Vec3 translation{0.0f};  // "<id>.to_world.translation": rigid motion applied on top of the geometry

  bool is_mesh() const { return std::holds_alternative<Mesh>(geometry); }
  bool is_sphere() const { return std::holds_alternative<Sphere>(geometry); }
  bool is_heightfield() const { return std::holds_alternative<Heightfield>(geometry); }
  const Heightfield& heightfield() const { return std::get<Heightfield>(geometry); }
  Heightfield& heightfield() { return std::get<Heightfield>(geometry); }
  const Mesh& mesh() const { return std::get<Mesh>(geometry); }
  Mesh& mesh() { return std::get<Mesh>(geometry); }
  const Sphere& sphere() const { return std::get<Sphere>(geometry); }
  Sphere& sphere() { return std::get<Sphere>(geometry); }

  float surface_area() const {
    return std::visit([](const auto& g) {
      if constexpr (std::is_same_v<std::decay_t<decltype(g)>, Mesh>) return g.total_area;
      else return g.area();
    }, geometry);
  }
  // Uniform point on the surface (pdf_area = 1 / area). Heightfields cannot be emitters (the
  // loader refuses), so nothing samples points on them.
  PositionSample sample_position(const Vec2& u, float u_extra) const {
    return std::visit([&](const auto& g) -> PositionSample {
      using T = std::decay_t<decltype(g)>;
      if constexpr (std::is_same_v<T, Mesh>) return g.sample_position(u, u_extra);
      else if constexpr (std::is_same_v<T, Sphere>) return g.sample_position(u);
      else throw std::logic_error("shape '" + id + "': heightfields have no position sampling (they cannot emit)");
    }, geometry);
  }
};

}  // namespace limn
