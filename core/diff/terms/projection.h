// Projective sampling (Zhang, Roussel, Jakob 2023, sections 3.1 and 5.2): an ordinary path
// segment x_a -> x_b that ends on a shape is moved onto a nearby boundary segment x_a -> x'_b,
// tangent to that shape's silhouette as seen from x_a, and returned as a point of the boundary
// sample space (core/diff/boundary_space.h) through its exact inverse.
//
// How a shape finds its silhouette is its kind's (BoundarySegments<G>::projector,
// core/diff/shapes/): spheres analytically (the paper's Listing 1), triangle meshes by WALK, JUMP
// and the hybrid of the two. When no silhouette is found a kind may snap to a nearby boundary
// point instead; Projection::found says which happened.
#pragma once
#include <memory>
#include <optional>
#include <unordered_map>
#include "core/diff/terms/boundary_space.h"
#include "core/math/rng.h"

namespace limn {

class Projector {
 public:
  Projector(const Scene& scene, const BoundarySpace& space, MeshProjection mode = MeshProjection::Hybrid);
  ~Projector();

  // Projects the segment from `xa` to the surface point `hit` (on any shape of the boundary
  // space). Nothing when the shape is not in the space or no boundary point can be built.
  std::optional<Projection> project(const Vec3& xa, const SurfaceInteraction& hit, Pcg32& rng) const;

 private:
  std::unordered_map<int, std::unique_ptr<ShapeProjector>> m_shapes;  // by shape index
};

}  // namespace limn
