// Disks in the derivative interface (core/diff/shapes/interface.h): centre (the translation) and
// radius on the tape, points attached at fixed unit-disk coordinates, the rim as the one perimeter
// segment of the boundary sample space (an open surface's boundary: a silhouette in every
// direction off its tangent and off the disk's plane), its projection, and the rim seen by the
// camera. A flat disk has no interior part (no curvature).
#pragma once
#include "core/diff/shapes/interface.h"

namespace limn {

template <>
struct SurfaceDiff<Disk> {
  static ad::V3<ad::Var> position(const DiffContext& c, const Disk& d, const SurfacePoint& sp);
  static DiffVertex attach(const DiffContext& c, const Disk& d, const SurfacePoint& sp);
  static DiffVertex ray_hit(const DiffContext& c, const Disk& d, const ad::V3<ad::Var>& o, const ad::V3<ad::Var>& dir,
                            const SurfaceInteraction& si, const Ray& primal_ray);
};

// The rim (perimeter part of Eq. 4): f is the angle along it / 2 pi, (u1, u2) the direction on
// S^2; measure dl dw (2 pi r x 4 pi).
template <>
struct BoundarySegments<Disk> {
  static constexpr const char* segment_name = "disk rims";
  static void append(const Scene& scene, const Disk& d, int shape, bool moving, BoundaryPart part, std::vector<BoundarySegment>& out);
  static bool sample(const Scene& scene, const Disk& d, const BoundarySegment& seg, float f, float u1, float u2, float pdf_select,
                     BoundaryPoint& out);
  static Vec3 invert(const Scene& scene, const Disk& d, const BoundarySegment& seg, const Vec3& xb, const Vec3& w);
  // Any rim point, with the light's own direction through it.
  static bool sample_delta(const Scene& scene, const Disk& d, const BoundarySegment& seg, float f, float pdf_select, const Emitter& light,
                           BoundaryPoint& out);
  static ad::V3<ad::Var> attached_point(const DiffContext& c, const Disk& d, const BoundarySegment& seg, const BoundaryPoint& p);
  static std::unique_ptr<ShapeProjector> projector(const Scene& scene, const Disk& d, const SegmentSpace& space, int shape,
                                                   const std::vector<int>& segments, MeshProjection mode);
};

// The rim seen from the camera (every point of it can be a silhouette of the open surface).
template <>
struct CameraSilhouettes<Disk> {
  static void append(const Scene& scene, const Disk& d, int shape, const CameraView& view, std::vector<SilhouetteCurve>& out,
                     uint64_t& skipped);
  static bool point(const DiffContext& c, const Disk& d, const SilhouetteCurve& curve, float u, const ad::V3<double>& eye,
                    ad::V3<ad::Var>& P, ad::V3<double>& dP, double& pdf_param);
  // The disk itself on the inner side of the rim.
  static void sides(const Scene& scene, const Disk& d, const SilhouetteCurve& curve, const Vec3& P, const ad::V3<double>& eye,
                    CurveSides& out);
};

}  // namespace limn
