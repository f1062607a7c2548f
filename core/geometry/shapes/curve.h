// Fibre curves: tubes around cubic uniform B-splines with a varying radius (projective-sampling
// paper, section 5.3; Mitsuba's `bsplinecurve`). docs/curves.md has the derivations.
//
//   M(u, v) = C(v) + r(v) rho(u, v),   rho = cos u N1(v) + sin u N2(v),   N1, N2 perpendicular to C'(v)
//
// C and r are one cubic uniform B-spline each (control points (x, y, z, r), Embree's basis); a
// curve of n >= 4 control points has n - 3 spans, span s of a curve using points s .. s + 3. The
// frame (N1, N2) rotates minimally along each curve (a discrete rotation-minimising frame), so it
// is continuous across span joints and never refers to a fixed axis.
//
// The frame is a function of the *local* tangent only, so that a point attached at (span, t, u)
// depends on its span's four control points alone (its derivative is local and exact): the RMF is
// built once on a rest copy of the centre line (rest_points), and at (s, t) the current frame is
// the rest frame there turned by the minimal rotation from the rest tangent to the current one.
// At rest it is the RMF; after edits it stays smooth and continuous (both factors are). The rest
// copy is refreshed when the curve structure changes or a tangent has turned by more than 60
// degrees from its rest direction (the minimal rotation degenerates at 180); that refresh is a
// discrete relabelling of u between two update() calls, never inside one derivative. The ends are open: no caps,
// the two rim circles are boundaries. The surface is one-sided: rays meet it from outside only
// (Embree also reports hits from inside; the intersection filter drops them).
//
// Radius limit: r(v) < 1 / kappa(v) (the curvature radius of C) everywhere, so that the
// cross-sections of neighbouring v do not cross and the area element r sqrt(a^2 + r'^2) with
// a = |C'| (1 - r rho.C''_perp / |C'|^2) stays positive. Loading and update() refuse violations
// (sampled at kCheckSamples points per span), zero-length spans (C' = 0) and radii <= 0, naming the
// curve and the control point.
#pragma once
#include <embree3/rtcore.h>
#include <string>
#include <vector>
#include "core/geometry/parameter.h"
#include "core/geometry/ray.h"
#include "core/geometry/shapes/mesh.h"
#include "core/math/distribution.h"

namespace limn {

// The B-spline and its derivatives at one parameter of one span, in double.
struct CurveSample {
  Vec3d c, c1, c2, c3;     // C, C', C'', C'''
  double r, r1, r2;        // r, r', r''
};

// The rotation about a x b taking unit a to unit b, applied to x (minimal rotation; a . b > -1).
inline Vec3d rotate_min(const Vec3d& a, const Vec3d& b, const Vec3d& x) {
  const Vec3d ab = a + b;
  return x - (glm::dot(ab, x) / (1.0 + glm::dot(a, b))) * ab + 2.0 * glm::dot(a, x) * b;
}

// The tube's local differential geometry at one point, in double (docs/curves.md). Built in a
// frame that does not twist at this point (rho_v along T only), so F = 0 up to rounding; every
// consumer still solves with the full first fundamental form, which makes the results independent
// of the frame (tests/cpp/geometry/test_curve.cpp checks this with a twisted frame).
struct TubeLocal {
  Vec3d p;                 // M(u, v)
  Vec3d t;                 // unit tangent of C
  Vec3d rho, b;            // unit radial direction, b = t x rho (the direction of growing u)
  Vec3d mu, mv;            // M_u, M_v
  Vec3d muu, muv, mvv;     // second derivatives
  Vec3d n;                 // unit outward normal, M_u x M_v / |M_u x M_v|
  double E, F, G;          // first fundamental form
  double L, M, N;          // second fundamental form, sign such that a convex direction is positive
  double area_density;     // |M_u x M_v| = r sqrt(a^2 + r'^2) per du dv
  // The 2x2 shape operator S = I^-1 II in the (M_u, M_v) basis: dn = S dM (convex positive).
  void shape_operator(double s[2][2]) const;
  // Normal curvature along the tangent vector w (projected onto the tangent plane first):
  // II(w, w) / I(w, w) with w's coordinates from the full 2x2 system [E F; F G] x = [w.M_u, w.M_v].
  double normal_curvature(const Vec3d& w) const;
  // |S w| for a unit tangent w: the speed at which the normal turns when the point moves along w
  // (the delta-light silhouette's Jacobian, docs/curves.md).
  double shape_operator_norm(const Vec3d& w) const;
  // n_u and n_v (Weingarten equations with the full forms).
  void normal_derivatives(Vec3d& nu, Vec3d& nv) const;
};
TubeLocal tube_local(const CurveSample& s, const Vec3d& rho);
// The same with an extra frame twist tau (rho_v gains tau b): a different parameterisation of the
// same surface, for tests of frame independence.
TubeLocal tube_local_twisted(const CurveSample& s, const Vec3d& rho, double tau);

// The silhouette condition at fixed v seen from a point e (or along a direction for lights at
// infinity): (M(u, v) - e) . (M_u x M_v) = 0 expanded as the paper's
//   A cos^2 u + B cos u sin u + C cos u + D sin u + E = 0   (section 5.3)
// in the curve's frame at v; linear in (cos u, sin u) when r' = 0.
struct SilhouetteEquation {
  double A = 0, B = 0, C = 0, D = 0, E = 0;
  double front = 0;        // the angle u facing e (the root on each side lies in (front, front +- pi))
  bool linear = false;     // r' == 0: closed form
  double eval(double u) const {
    const double c = std::cos(u), s = std::sin(u);
    return A * c * c + B * c * s + C * c + D * s + E;
  }
};

struct BSplineCurve {
  static constexpr const char* kind_name = "bsplinecurve";
  static constexpr bool can_emit = false;
  static constexpr int kFrameSamples = 8;   // frame table entries per span (rotation-minimising steps)
  static constexpr int kBins = 16;          // sampling bins per span (the interior boundary segment)
  static constexpr int kCheckSamples = 64;  // radius-limit and zero-length checks per span

  std::vector<float> control_points;   // 4 floats per point: x, y, z (world space) and radius; "<id>.control_points"
  std::vector<uint32_t> curve_offsets; // first control point of each curve, then the total count
  std::string source;                  // where the curves came from (file or "<arrays>"), for messages

  // Derived state (build_derived): spans, the frame table, areas and the sampling bins.
  std::vector<uint32_t> span_first;    // per span: its first control point (Embree's index buffer)
  std::vector<uint32_t> span_curve;    // per span: its curve
  std::vector<float> rest_points;      // the control points the frame table was built on
  std::vector<Vec3d> frame_n1;         // per span kFrameSamples + 1 entries: rest N1 at t = j / kFrameSamples
  std::vector<Vec3d> frame_t;          // the rest unit tangent there
  std::vector<Vec3> span_lo, span_hi;  // per span: bounding box of its tube
  std::vector<double> bin_area;        // per span kBins: the tube's area over that stretch of t
  Distribution1D bins;                 // over all spans' bins, by area / radius (about 2 pi x length)
  double total_area = 0.0;

  size_t point_count() const { return control_points.size() / 4; }
  size_t curve_count() const { return curve_offsets.empty() ? 0 : curve_offsets.size() - 1; }
  size_t span_count() const { return span_first.size(); }
  Vec3 point(size_t i) const { return Vec3(control_points[4 * i], control_points[4 * i + 1], control_points[4 * i + 2]); }
  // The spans of curve k: [first_span(k), first_span(k) + spans_of(k)).
  uint32_t first_span(size_t k) const { return curve_offsets[k] - 3 * uint32_t(k); }
  uint32_t spans_of(size_t k) const { return curve_offsets[k + 1] - curve_offsets[k] - 3; }

  // The B-spline of span s at local parameter t (any real t: the span's polynomial).
  CurveSample eval(size_t s, double t) const;
  // N1 of the frame at (s, t) for the unit tangent `t_unit` there (t clamped to [0, 1]).
  Vec3d frame(size_t s, double t, const Vec3d& t_unit) const;
  // The rest centre line's unit tangent at (s, t) and its rest N1 (the frame before the final
  // minimal rotation to the current tangent; constants for the derivative code).
  void rest_frame(size_t s, double t, Vec3d& t_rest, Vec3d& n1_rest) const;
  // The radial direction rho for angle u at (s, t), and the local geometry there.
  Vec3d radial(size_t s, double t, double u) const;
  TubeLocal local(size_t s, double t, double u) const { return tube_local(eval(s, t), radial(s, t, u)); }
  // The angle u of a radial direction at (s, t), in [0, 2 pi).
  double angle_of(size_t s, double t, const Vec3d& rho) const;
  // The silhouette equation at (s, t) seen from point e (directional = false) or for rays along
  // direction e (directional = true).
  SilhouetteEquation silhouette_equation(size_t s, double t, const Vec3d& e, bool directional) const;
  // The root on side +1 or -1 of the front-facing angle: closed form when linear, else bisection
  // of the bracket [front, front +- pi] (`steps` halvings; the paper uses 20). False when the
  // bracket holds no sign change (e is inside the cross-section's cylinder): a reported failure.
  static bool silhouette_root(const SilhouetteEquation& q, int side, int steps, double& u);

  // Ray against the tube of span s by Newton on (v, t) in double from a start (v0, t0):
  // (P(t) - C(v)) . C'(v) = 0 and |P(t) - C(v)|^2 = r(v)^2. Returns false without convergence.
  bool refine_hit(size_t s, const Vec3d& o, const Vec3d& d, double& v, double& t) const;
  // Embree's candidate hit (span s at (v, t)) as an exact hit seen from outside, possibly moved
  // to a neighbouring span at a joint; false to reject it.
  bool accept_hit(unsigned& s, const Vec3d& o, const Vec3d& d, float tnear, double& v, double& t, double& u, Vec3d& n) const;

  // Checks a control point buffer (4 floats per point) against the curve structure: finite,
  // radii > 0, no zero-length span, radius below the curvature radius. Returns "" or the problem,
  // naming the curve and the control point.
  std::string check(const float* cps) const;
  // Global parameter of (span, t) along its own curve, in [0, 1] (texture coordinate).
  float curve_parameter(size_t s, double t) const;

  // ---- the shape interface (core/geometry/shapes/shape.h) ----
  void build_derived();
  // Embree round B-spline curve with the intersection and occlusion filters (outside hits only,
  // refined in double).
  RTCGeometry create_embree_geometry(RTCDevice device) const;
  void update_embree_geometry(RTCGeometry g) const;  // uploads the control points
  // The filtered hit: uv = (v on span prim, u / 2 pi) as the filter stored it.
  void fill_hit(const Ray& ray, float t, unsigned prim, const Vec2& uv, SurfaceInteraction& si) const;
  float area() const { return float(total_area); }
  // "<id>.control_points" (N x 4: position and radius).
  void list_parameters(const std::string& id, int index, std::vector<Parameter>& out);
  void validate_parameter(const Parameter& p, const std::string& where) const;
  void apply_parameter(const Parameter&) { build_derived(); }
  void translate(const Vec3& delta);
  void bounds(Vec3& lo, Vec3& hi) const;
  void geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const;
};

}  // namespace limn
