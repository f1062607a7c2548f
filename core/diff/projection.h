// Projective sampling (Zhang, Roussel, Jakob 2023, sections 3.1 and 5.2): an ordinary path
// segment x_a -> x_b that ends on a shape is moved onto a nearby boundary segment x_a -> x'_b,
// tangent to that shape's silhouette as seen from x_a, and returned as a point of the boundary
// sample space (core/diff/boundary_space.h) through its exact inverse.
//
//   - spheres: analytic (the paper's Listing 1);
//   - triangle meshes: WALK (greedy over adjacent triangles towards the silhouette seen from x_a,
//     choosing at random between the two best neighbours in proportion to their angle), JUMP (a
//     local linear model of position and interpolated normal, its analytic silhouette line, then a
//     ray along -n back onto the surface), and the hybrid 30 WALK, 1 JUMP, 30 WALK.
// When no silhouette is found the point snaps to the closest edge of the last triangle that is in
// the boundary space and the direction to the tangential one closest to the original; `found`
// says which happened.
#pragma once
#include <optional>
#include <unordered_map>
#include "core/diff/boundary_space.h"
#include "core/math/rng.h"

namespace limn {

struct Projection {
  Vec3 u;            // point of the boundary sample space
  int segment;       // its segment (edge or sphere) in the boundary space
  Vec3 xb, w;        // the boundary point and the direction from it towards (a slightly shifted) x_a
  bool found;        // a true silhouette; false: the snapped fallback
};

enum class MeshProjection { Walk, Jump, Hybrid };

class Projector {
 public:
  Projector(const Scene& scene, const BoundarySpace& space, MeshProjection mode = MeshProjection::Hybrid);

  // Projects the segment from `xa` to the surface point `hit` (on any shape of the boundary
  // space). Nothing when the shape is not in the space or no boundary point can be built.
  std::optional<Projection> project(const Vec3& xa, const SurfaceInteraction& hit, Pcg32& rng) const;

 private:
  std::optional<Projection> project_sphere(const Vec3& xa, const SurfaceInteraction& hit) const;
  std::optional<Projection> project_mesh(const Vec3& xa, const SurfaceInteraction& hit, Pcg32& rng) const;
  // Greedy walk from triangle f; returns the silhouette edge's segment nearest to `near` among
  // those of the first triangle that has any, or -1 (f is updated).
  int walk(int shape, const Vec3& xa, const Vec3& near, int& f, int steps, Pcg32& rng, int& taken) const;
  // One JUMP from point p on triangle f; lands on triangle f (updated) at p (updated).
  bool jump(int shape, const Vec3& xa, int& f, Vec3& p) const;
  // The boundary point on `segment` nearest to `near`, with the original segment direction w_orig
  // if it sees a silhouette there, else the direction to xa.
  std::optional<Projection> finish(int segment, const Vec3& xa, const Vec3& near, bool found, const Vec3& w_orig) const;
  std::optional<Projection> snap(int shape, int f, const Vec3& xa, const Vec3& p) const;

  struct MeshTopology {
    std::vector<int> neighbour;   // 3 per triangle: the triangle across edge k (k = corner k -> k+1), -1 if none or non-manifold
    std::vector<int> segment;     // 3 per triangle: boundary-space segment of that edge, -1 if not in the space
    std::vector<Vec3> normals;    // area-weighted vertex normals (JUMP's interpolated normal; flat meshes have none)
  };
  const Scene& m_scene;
  const BoundarySpace& m_space;
  MeshProjection m_mode;
  std::unordered_map<int, MeshTopology> m_meshes;  // by shape
  std::unordered_map<int, int> m_sphere_segment;   // shape -> segment
};

}  // namespace limn
