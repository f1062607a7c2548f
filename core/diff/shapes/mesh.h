// Triangle meshes in the derivative interface (core/diff/shapes/interface.h): vertices on the tape,
// points attached at fixed barycentrics, edges as the perimeter segments of the boundary sample
// space, the WALK / JUMP projection onto silhouette edges (projective-sampling paper, section 5.2),
// and silhouette edges seen by the camera.
#pragma once
#include "core/diff/shapes/interface.h"

namespace limn {

// Vertex i of mesh `shape` on the tape (with the shape's translation parameter).
ad::V3<ad::Var> mesh_vertex(const DiffContext& c, int shape, uint32_t i);

template <>
struct SurfaceDiff<Mesh> {
  static ad::V3<ad::Var> position(const DiffContext& c, const Mesh& m, const SurfacePoint& sp);
  static DiffVertex attach(const DiffContext& c, const Mesh& m, const SurfacePoint& sp);
  static DiffVertex ray_hit(const DiffContext& c, const Mesh& m, const ad::V3<ad::Var>& o, const ad::V3<ad::Var>& d,
                            const SurfaceInteraction& si, const Ray& primal_ray);
};

// Edges (perimeter part of Eq. 4): the remapped first coordinate is the position along the edge,
// the other two a direction on S^2; measure dl dw (4 pi length), also the weight. Only edges that can be
// silhouettes take part, in Morton order of their midpoints.
template <>
struct BoundarySegments<Mesh> {
  static constexpr const char* segment_name = "edges";
  static void append(const Scene& scene, const Mesh& m, int shape, bool moving, BoundaryPart part, std::vector<BoundarySegment>& out);
  static bool sample(const Scene& scene, const Mesh& m, const BoundarySegment& s, float f, float u1, float u2, float pdf_select,
                     BoundaryPoint& out);
  static Vec3 invert(const Scene& scene, const Mesh& m, const BoundarySegment& s, const Vec3& xb, const Vec3& w);
  static bool sample_delta(const Scene& scene, const Mesh& m, const BoundarySegment& s, float f, float pdf_select, const Emitter& light,
                           BoundaryPoint& out);
  static ad::V3<ad::Var> attached_point(const DiffContext& c, const Mesh& m, const BoundarySegment& s, const BoundaryPoint& p);
  static std::unique_ptr<ShapeProjector> projector(const Scene& scene, const Mesh& m, const SegmentSpace& space, int shape,
                                                   const std::vector<int>& segments, MeshProjection mode);
};

// Edges that can be silhouettes from the camera centre (boundary, non-manifold, or between a
// front- and a back-facing triangle) and creases of flat-shaded meshes (the shading jumps there).
template <>
struct CameraSilhouettes<Mesh> {
  static void append(const Scene& scene, const Mesh& m, int shape, const CameraView& view, std::vector<SilhouetteCurve>& out,
                     uint64_t& skipped);
  static bool point(const DiffContext& c, const Mesh& m, const SilhouetteCurve& curve, float u, const ad::V3<double>& eye,
                    ad::V3<ad::Var>& P, ad::V3<double>& dP, double& pdf_param);
  // The edge's distinct triangles at P (two for a crease or silhouette, one for an open edge).
  static void sides(const Scene& scene, const Mesh& m, const SilhouetteCurve& curve, const Vec3& P, const ad::V3<double>& eye,
                    CurveSides& out);
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
