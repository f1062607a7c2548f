// Every shape kind's derivative code, checked against the interface (interface.h), and the
// dispatchers the kind-independent code calls. Dispatch is std::visit: a kind without a group's
// specialisation does not compile; a kind whose group is Unsupported is refused by name.
#pragma once
#include <stdexcept>
#include "core/diff/shapes/curve.h"
#include "core/diff/shapes/disk.h"
#include "core/diff/shapes/heightfield.h"
#include "core/diff/shapes/mesh.h"
#include "core/diff/shapes/sdfgrid.h"
#include "core/diff/shapes/sphere.h"

namespace limn {

template <typename... Kinds>
constexpr bool all_differentiable_kinds(const std::variant<Kinds...>*) {
  return (DifferentiableShapeKind<Kinds> && ...);
}
static_assert(all_differentiable_kinds(static_cast<const ShapeGeometry*>(nullptr)),
              "every alternative of ShapeGeometry must implement the derivative interface (core/diff/shapes/interface.h)");

// ---- surface points ---------------------------------------------------------------------------
inline ad::V3<ad::Var> attached_position(const DiffContext& c, const SurfacePoint& sp) {
  return c.scene.shapes[sp.shape].visit([&](const auto& g) { return SurfaceDiff<std::decay_t<decltype(g)>>::position(c, g, sp); });
}
inline DiffVertex attach(const DiffContext& c, const SurfacePoint& sp) {
  return c.scene.shapes[sp.shape].visit([&](const auto& g) { return SurfaceDiff<std::decay_t<decltype(g)>>::attach(c, g, sp); });
}
inline DiffVertex ray_hit(const DiffContext& c, const ad::V3<ad::Var>& o, const ad::V3<ad::Var>& d, const SurfaceInteraction& si,
                          const Ray& primal_ray) {
  return c.scene.shapes[si.shape].visit(
      [&](const auto& g) { return SurfaceDiff<std::decay_t<decltype(g)>>::ray_hit(c, g, o, d, si, primal_ray); });
}

// ---- groups a kind may lack -------------------------------------------------------------------
// f(group, geometry) -> R with the kind's group, when the kind has it; otherwise throws
// std::invalid_argument naming the scene, the shape and the reason (for set-up code, never inside
// render loops).
template <template <typename> class Group, typename R = void, typename F>
R with_group(const Scene& scene, int shape, const char* what, F&& f) {
  const Shape& sh = scene.shapes[size_t(shape)];
  return sh.visit([&](const auto& g) -> R {
    using G = std::decay_t<decltype(g)>;
    if constexpr (is_unsupported<Group<G>>)
      throw std::invalid_argument(scene.source + ": shape '" + sh.id + "' (" + G::kind_name + ") has no " + what + ": " +
                                  Group<G>::reason);
    else
      return f(Group<G>{}, g);
  });
}

// Whether shape's kind has the group (without calling it).
template <template <typename> class Group>
bool has_group(const Shape& sh) {
  return sh.visit([](const auto& g) { return !is_unsupported<Group<std::decay_t<decltype(g)>>>; });
}

}  // namespace limn
