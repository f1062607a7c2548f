// B-spline fibre curves in the derivative interface (core/diff/shapes/interface.h): control points
// and radii on the tape, points attached at fixed (span, t, u), the tube as the interior part of
// Eq. 4 (normal curvature from the full fundamental forms) and its open rims as the perimeter part,
// the projection at fixed v (projective-sampling paper, section 5.3), and the tube's silhouettes
// and rim circles seen by the camera. docs/curves.md has the derivations.
#pragma once
#include "core/diff/shapes/interface.h"

namespace limn {

// Control point i of curve `shape` on the tape: position (with the shape's translation) and radius.
void curve_point(const DiffContext& c, int shape, uint32_t i, ad::V3<ad::Var>& p, ad::Var& r);

// The attached point M(u, v) at (span, t) with the primal radial direction rho0 held fixed: on the
// tape rho is rho0 made perpendicular to the moved tangent (a smooth family of parameterisations,
// equal to the primal one at theta; the frame's twist does not enter the area element or normal).
ad::V3<ad::Var> curve_position(const DiffContext& c, const BSplineCurve& g, int shape, size_t span, double t, const Vec3d& rho0);

template <>
struct SurfaceDiff<BSplineCurve> {
  static ad::V3<ad::Var> position(const DiffContext& c, const BSplineCurve& g, const SurfacePoint& sp);
  static DiffVertex attach(const DiffContext& c, const BSplineCurve& g, const SurfacePoint& sp);
  static DiffVertex ray_hit(const DiffContext& c, const BSplineCurve& g, const ad::V3<ad::Var>& o, const ad::V3<ad::Var>& d,
                            const SurfaceInteraction& si, const Ray& primal_ray);
};

// Interior segment (one per shape, local 0): the first coordinate picks a stretch of v over all
// spans of all curves (bins by area / radius), u1 the angle u around, u2 the tangential direction's
// angle; measure dA dphi (2 pi area), pdf per dA dphi; zero where the normal curvature along w is
// not positive (the tangent line enters the tube: no silhouette). Perimeter segments (local k =
// 2 curve + end): the rim circles, u.x along the rim, (u1, u2) a direction on the outer hemisphere
// (the surface is one-sided: rays meet it from outside only); measure dl dw (4 pi^2 r).
template <>
struct BoundarySegments<BSplineCurve> {
  static constexpr const char* segment_name = "curve tubes and rims";
  static void append(const Scene& scene, const BSplineCurve& g, int shape, bool moving, BoundaryPart part,
                     std::vector<BoundarySegment>& out);
  static bool sample(const Scene& scene, const BSplineCurve& g, const BoundarySegment& seg, float f, float u1, float u2, float pdf_select,
                     BoundaryPoint& out);
  static Vec3 invert(const Scene& scene, const BSplineCurve& g, const BoundarySegment& seg, const Vec3& xb, const Vec3& w);
  // Point and directional lights: the tube's silhouette seen from the light (the root of the
  // silhouette equation at v, one side chosen by u.x), measure dl along it, Jacobian
  // kappa_n(w) / |S w|; the rims where the light's direction reaches their outer side.
  static bool sample_delta(const Scene& scene, const BSplineCurve& g, const BoundarySegment& seg, float f, float pdf_select,
                           const Emitter& light, BoundaryPoint& out);
  static ad::V3<ad::Var> attached_point(const DiffContext& c, const BSplineCurve& g, const BoundarySegment& seg, const BoundaryPoint& p);
  static std::unique_ptr<ShapeProjector> projector(const Scene& scene, const BSplineCurve& g, const SegmentSpace& space, int shape,
                                                   const std::vector<int>& segments, MeshProjection mode);
};

// Silhouette curves seen from the camera centre: per span two (local 2 span + side), the roots of
// the silhouette equation on either side of the front-facing angle; then the rim circles (local
// 2 spans + rim).
template <>
struct CameraSilhouettes<BSplineCurve> {
  static void append(const Scene& scene, const BSplineCurve& g, int shape, const CameraView& view, std::vector<SilhouetteCurve>& out,
                     uint64_t& skipped);
  static bool point(const DiffContext& c, const BSplineCurve& g, const SilhouetteCurve& curve, float u, const ad::V3<double>& eye,
                    ad::V3<ad::Var>& P, ad::V3<double>& dP, double& pdf_param);
  // None: a smooth tube's outline and its rims are shaded by probe rays.
  static void sides(const Scene&, const BSplineCurve&, const SilhouetteCurve&, const Vec3&, const ad::V3<double>&, CurveSides& out) {
    out.count = 0;
  }
};

// Locates the surface point nearest to x on the tube (for exact inverses): span, t and u; false
// when x is not within 1e-4 of the radius from the surface.
bool curve_locate(const BSplineCurve& g, const Vec3& x, size_t& span, double& t, double& u);

}  // namespace limn
