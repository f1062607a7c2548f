// Spheres in the derivative interface (core/diff/shapes/interface.h): centre and radius on the
// tape, points attached at a fixed direction from the centre, the surface as an interior segment
// of the boundary sample space (normal curvature 1/r in every direction), the analytic projection
// (projective-sampling paper, Listing 1), and the outline circle seen by the camera.
#pragma once
#include "core/diff/shapes/interface.h"

namespace limn {

// Centre and radius of sphere `shape` on the tape (the centre with the translation parameter).
ad::V3<ad::Var> sphere_center(const DiffContext& c, int shape);
ad::Var sphere_radius(const DiffContext& c, int shape);

template <>
struct SurfaceDiff<Sphere> {
  static ad::V3<ad::Var> position(const DiffContext& c, const Sphere& s, const SurfacePoint& sp);
  static DiffVertex attach(const DiffContext& c, const Sphere& s, const SurfacePoint& sp);
  static DiffVertex ray_hit(const DiffContext& c, const Sphere& s, const ad::V3<ad::Var>& o, const ad::V3<ad::Var>& d,
                            const SurfaceInteraction& si, const Ray& primal_ray);
};

// The surface (interior part of Eq. 4): (remapped first coordinate, u1) is the point on the
// sphere, u2 the tangential direction's angle; measure dA dphi (area x 2 pi), weight 8 pi^2 r (the
// measure times the curvature 1/r).
template <>
struct BoundarySegments<Sphere> {
  static constexpr const char* segment_name = "sphere surfaces";
  static void append(const Scene& scene, const Sphere& s, int shape, bool moving, BoundaryPart part, std::vector<BoundarySegment>& out);
  static bool sample(const Scene& scene, const Sphere& s, const BoundarySegment& seg, float f, float u1, float u2, float pdf_select,
                     BoundaryPoint& out);
  static Vec3 invert(const Scene& scene, const Sphere& s, const BoundarySegment& seg, const Vec3& xb, const Vec3& w);
  // The silhouette circle seen from the light: w is the light's direction through it.
  static bool sample_delta(const Scene& scene, const Sphere& s, const BoundarySegment& seg, float f, float pdf_select,
                           const Emitter& light, BoundaryPoint& out);
  static ad::V3<ad::Var> attached_point(const DiffContext& c, const Sphere& s, const BoundarySegment& seg, const BoundaryPoint& p);
  static std::unique_ptr<ShapeProjector> projector(const Scene& scene, const Sphere& s, const SegmentSpace& space, int shape,
                                                   const std::vector<int>& segments, MeshProjection mode);
};

// The outline circle seen from the camera centre.
template <>
struct CameraSilhouettes<Sphere> {
  static void append(const Scene& scene, const Sphere& s, int shape, const CameraView& view, std::vector<SilhouetteCurve>& out,
                     uint64_t& skipped);
  static bool point(const DiffContext& c, const Sphere& s, const SilhouetteCurve& curve, float u, const ad::V3<double>& eye,
                    ad::V3<ad::Var>& P, ad::V3<double>& dP, double& pdf_param);
  // None: a smooth outline's inner probe ray lands on the sphere itself.
  static void sides(const Scene&, const Sphere&, const SilhouetteCurve&, const Vec3&, const ad::V3<double>&, CurveSides& out) {
    out.count = 0;
  }
};

}  // namespace limn
