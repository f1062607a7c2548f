// Boundary sample space of the indirect boundary term (projective-sampling paper, Eq. 4 and
// section 5.2): [0,1)^3 -> (segment, boundary point x_b, direction w), with an exact inverse.
//
// Segments of the space, chosen by u.x in proportion to their measure:
//   - mesh edges that can be silhouettes (perimeter part of Eq. 4): the remapped u.x is the
//     position along the edge, (u.y, u.z) a direction on S^2; measure dl dw, weight 4 pi length;
//   - sphere surfaces (interior part of Eq. 4, normal curvature 1/r): (remapped u.x, u.y) is the
//     point on the sphere, u.z the tangential direction angle; measure dA dphi, weight 8 pi^2 r
//     (area x 2 pi x curvature).
// Static shapes take part too (a segment grazing a static silhouette moves when it ends on a moving
// surface); together they get at most a quarter of the first coordinate.
// Point and directional lights put Dirac deltas into the integrand; sample_delta() maps u.x alone
// onto the curve where the light's direction grazes the boundary (any point of an edge; the
// sphere's silhouette circle seen from the light), measure dl.
//
// Projective sampling (issue 5) finds (segment, x_b, w) by projection and stores invert(...) in
// a guiding structure; sample() must reproduce the same point from it.
#pragma once
#include <optional>
#include "core/diff/diff_params.h"
#include "core/math/distribution.h"

namespace limn {

struct BoundarySegment {
  enum class Kind { MeshEdge, SphereSurface } kind;
  int shape;
  bool moving;                 // the shape's geometry is differentiable
  uint32_t a = 0, b = 0;       // edge vertices
  int face0 = -1, face1 = -1;  // adjacent triangles (face1 = -1 on a boundary or non-manifold edge)
  int edge = -1;               // index into the mesh's edges (all of its triangles)
};

struct BoundaryPoint {
  int segment = -1;
  Vec3 xb{0.0f};     // point on the boundary
  Vec3 w{0.0f};      // unit direction from x_b towards the observing side
  Vec3 n_b{0.0f};    // unit normal of the boundary, perpendicular to w, pointing away from the occluder
  Vec3 n_out{0.0f};  // offset that moves a ray start off the surface (importance rays)
  float jacobian = 0.0f;  // sin(phi) between edge and w (perimeter), or the normal curvature (interior)
  float pdf = 0.0f;       // density per unit measure (dl dw, dA dphi, or dl for delta lights)
  float delta = 0.0f;     // radiance probe offset along n_b
  Vec3 param{0.0f};       // where x_b sits on its segment: (lambda, 0, 0) on an edge, the unit normal on a sphere
};

class BoundarySpace {
 public:
  BoundarySpace(const Scene& scene, const DiffParams& params);

  bool empty() const { return m_segments.empty(); }
  size_t edge_count() const { return m_edges; }
  size_t sphere_count() const { return m_segments.size() - m_edges; }
  size_t static_count() const;  // segments of shapes that do not move
  const std::vector<BoundarySegment>& segments() const { return m_segments; }

  // The point for u, drawn with density pdf_u on [0,1)^3. False where the integrand is zero by
  // construction (w does not see the edge as a silhouette) or the point is degenerate.
  bool sample(const Vec3& u, float pdf_u, BoundaryPoint& out) const;
  // Exact inverse of sample() for a point x_b on `segment` and a direction w (sample(invert(..))
  // gives back x_b and w up to rounding).
  Vec3 invert(int segment, const Vec3& xb, const Vec3& w) const;

  // The delta-light point for u0 (density pdf_u0 of the first coordinate): w is the light's
  // direction through x_b. False when that direction does not graze the boundary there.
  bool sample_delta(float u0, float pdf_u0, const Emitter& light, BoundaryPoint& out) const;

  // x_b attached to the differentiable geometry (edge barycentric or sphere direction fixed).
  ad::V3<ad::Var> attached_point(const BoundaryPoint& p, PathInputs& in) const;

 private:
  float select(float u0, size_t* segment) const;
  bool finish_edge(const BoundarySegment& s, float lambda, const Vec3& w, BoundaryPoint& out) const;
  void finish_sphere(const BoundarySegment& s, const Vec3& n, const Vec3& w, BoundaryPoint& out) const;

  const Scene& m_scene;
  const DiffParams& m_params;
  std::vector<BoundarySegment> m_segments;  // edges first (moving shapes first), then spheres
  std::vector<float> m_measure;             // per segment: its weight (see above)
  size_t m_edges = 0;
  Distribution1D m_select;
  double m_total = 0.0;
};

// The mesh edges that can be silhouettes from some direction: boundary, non-manifold and convex
// non-flat edges.
bool edge_can_be_silhouette(const Mesh& m, const MeshEdge& e);

// The silhouette rule of the indirect term and of the projections: edge e is a silhouette for rays
// along d (any length) when all of its triangles lie on one side of the plane through the edge and
// d; a ray beside the edge then meets triangles on that side only. Returns that side, +1 where
// (b - a) x d points (towards the triangles: n_b is the other way), -1 the other, 0 when they
// straddle the plane or one lies in it. Winding-free; for the two triangles of a convex edge it is
// "one faces d, the other away"; an open edge is a silhouette for every d off its triangle's plane.
int edge_side(const Mesh& m, const MeshEdge& e, const Vec3& d);

}  // namespace limn
