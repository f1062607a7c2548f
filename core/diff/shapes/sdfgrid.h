// Signed-distance grids in the derivative interface (core/diff/shapes/interface.h); docs/sdf.md.
//
// Attached points: a surface point is attached by its local position l (SurfaceInteraction uv =
// (l.x, l.y), bary.x = l.z) and moves along the line l + tau D(l), D = P(s) grad f / |grad f| in
// grid coordinates with P = diag(4 s_i (1 - s_i)) over the voxel-local coordinates s: its normal
// velocity is the implicit-function derivative -(df/dtheta) / |grad f|, and on a voxel face D lies
// in the face, so a point on a crease (where the normal jumps) stays on it. Creases are then fixed
// in the material coordinates and the interior term needs no extra boundary term for the shading
// jump across them (docs/sdf.md, "Attached points").
//
// Boundary sample space (projective-sampling paper Eq. 4 and section 5.4):
//   interior   one segment per voxel the surface passes through: (a, b) the voxel-local
//              coordinates across its axis (SdfGrid::voxel_axis, stored in the segment), the
//              surface point on the line along the axis (f is linear there: one root), the angle
//              of the tangential direction; measure dA dphi, Jacobian the normal curvature
//              w^T H w / |grad f| (world), positive where w sees a silhouette
//   perimeter  one segment per voxel face the surface crosses (the normal jumps there): the
//              crease as a graph over one face axis, a direction on S^2; measure dl dw, Jacobian
//              sin(phi); a silhouette along w where both patches leave the crease on the same side
//              of the plane through its tangent and w (on the grid's boundary, one patch)
// Projection: Gauss-Newton on (f, (x - x_a) . grad f) = 0 from the hit, voxel by voxel, snapping to
// a crease that is a silhouette where the march crosses a face (docs/derivatives.md).
#pragma once
#include "core/diff/shapes/interface.h"

namespace limn {

template <>
struct SurfaceDiff<SdfGrid> {
  static ad::V3<ad::Var> position(const DiffContext& c, const SdfGrid& g, const SurfacePoint& sp);
  static DiffVertex attach(const DiffContext& c, const SdfGrid& g, const SurfacePoint& sp);
  static DiffVertex ray_hit(const DiffContext& c, const SdfGrid& g, const ad::V3<ad::Var>& o, const ad::V3<ad::Var>& d,
                            const SurfaceInteraction& si, const Ray& primal_ray);
};

template <>
struct BoundarySegments<SdfGrid> {
  static constexpr const char* segment_name = "SDF voxels and creases";
  static void append(const Scene& scene, const SdfGrid& g, int shape, bool moving, BoundaryPart part, std::vector<BoundarySegment>& out);
  static bool sample(const Scene& scene, const SdfGrid& g, const BoundarySegment& s, float f, float u1, float u2, float pdf_select,
                     BoundaryPoint& out);
  static Vec3 invert(const Scene& scene, const SdfGrid& g, const BoundarySegment& s, const Vec3& xb, const Vec3& w);
  // The light's grazing curve: the contour seen from the light inside a voxel (interior), or the
  // points of a crease where the light's direction makes it a silhouette (perimeter).
  static bool sample_delta(const Scene& scene, const SdfGrid& g, const BoundarySegment& s, float f, float pdf_select, const Emitter& light,
                           BoundaryPoint& out);
  static ad::V3<ad::Var> attached_point(const DiffContext& c, const SdfGrid& g, const BoundarySegment& s, const BoundaryPoint& p);
  static std::unique_ptr<ShapeProjector> projector(const Scene& scene, const SdfGrid& g, const SegmentSpace& space, int shape,
                                                   const std::vector<int>& segments, MeshProjection mode);
};

// Curves seen from the camera: every crease (shading jumps across it; where it is a silhouette,
// visibility too) and, per voxel, the contour f = 0, (x - eye) . grad f = 0.
template <>
struct CameraSilhouettes<SdfGrid> {
  static void append(const Scene& scene, const SdfGrid& g, int shape, const CameraView& view, std::vector<SilhouetteCurve>& out,
                     uint64_t& skipped);
  static bool point(const DiffContext& c, const SdfGrid& g, const SilhouetteCurve& curve, float u, const ad::V3<double>& eye,
                    ad::V3<ad::Var>& P, ad::V3<double>& dP, double& pdf_param);
  // None: both sides are shaded by probe rays, which the crease test (probes_see_patches) checks.
  static void sides(const Scene&, const SdfGrid&, const SilhouetteCurve&, const Vec3&, const ad::V3<double>&, CurveSides& out) {
    out.count = 0;
  }
};

// ---- helpers shared with the tests ---------------------------------------------------------------
namespace sdf {

// A voxel face: the face perpendicular to axis d whose lowest corner is grid sample (i, j, k).
struct Face {
  int i, j, k, d;
  static Face of_code(const SdfGrid& g, int code);
  int code(const SdfGrid& g) const { return int(g.sample_index(i, j, k)) * 3 + d; }
};

// A crease point: on face `face`, at coordinate r along axis `along` (one of the face's two axes)
// and o along the other; false if the crease has no point at r inside the face.
struct CreasePoint {
  Vec3d g;          // grid position
  Vec3d tangent;    // world, unit
  double dl_dr;     // world length per unit r
  double o, do_dr;  // the other coordinate and its derivative
};
bool crease_point(const SdfGrid& g, const Face& face, int along, double r, CreasePoint& out, bool clamp_inside = true);

// The contour seen from e (grid coordinates; a direction when `directional`) in voxel v on the
// graph x(a, b) of `axis`: the roots of (x(a, b) - e) . grad f = 0 (or e . grad f) along the line
// where graph coordinate `held` (0: a, 1: b) equals `at`, where the surface point is inside the
// voxel; the other coordinate of at most `max` of them, ordered.
int contour_roots(const SdfGrid& g, uint32_t v, int axis, int held, double at, const Vec3d& e, bool directional, double* out, int max);

// Success counters of the projection (all threads; for reports).
struct ProjectionStats {
  uint64_t tried = 0, interior = 0, crease = 0, fallback = 0, failed = 0;
};
ProjectionStats projection_stats();
void reset_projection_stats();

}  // namespace sdf

}  // namespace limn
