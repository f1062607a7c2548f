#include "core/geometry/shapes/curve.h"

#include <cstring>
#include <sstream>
#include <stdexcept>

namespace limn {
namespace {

constexpr double kTwoPi = 2.0 * M_PI;

// Cubic uniform B-spline basis (Embree's) and its derivatives at t, for the 4 points of a span.
void basis(double t, double w[4], double w1[4], double w2[4], double w3[4]) {
  const double s = 1.0 - t, t2 = t * t, t3 = t2 * t;
  w[0] = s * s * s / 6.0, w[1] = (3 * t3 - 6 * t2 + 4) / 6.0, w[2] = (-3 * t3 + 3 * t2 + 3 * t + 1) / 6.0, w[3] = t3 / 6.0;
  w1[0] = -0.5 * s * s, w1[1] = 0.5 * (3 * t2 - 4 * t), w1[2] = 0.5 * (-3 * t2 + 2 * t + 1), w1[3] = 0.5 * t2;
  w2[0] = s, w2[1] = 3 * t - 2, w2[2] = -3 * t + 1, w2[3] = t;
  w3[0] = -1, w3[1] = 3, w3[2] = -3, w3[3] = 1;
}

CurveSample eval_points(const float* cps, uint32_t first, double t) {
  double w[4], w1[4], w2[4], w3[4];
  basis(t, w, w1, w2, w3);
  CurveSample s{};
  for (int k = 0; k < 4; ++k) {
    const float* q = cps + 4 * size_t(first + uint32_t(k));
    const Vec3d p(q[0], q[1], q[2]);
    s.c += w[k] * p, s.c1 += w1[k] * p, s.c2 += w2[k] * p, s.c3 += w3[k] * p;
    s.r += w[k] * q[3], s.r1 += w1[k] * q[3], s.r2 += w2[k] * q[3];
  }
  return s;
}

// A unit vector perpendicular to unit n (Duff et al. 2017), only to start each curve's frame.
Vec3d any_perpendicular(const Vec3d& n) {
  const double sign = std::copysign(1.0, n.z), a = -1.0 / (sign + n.z), b = n.x * n.y * a;
  return Vec3d(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
}

// The tangent's derivatives: T_v = C''_perp / |C'| and T_vv (docs/curves.md).
void tangent_derivatives(const CurveSample& s, Vec3d& t, Vec3d& tv, Vec3d& tvv) {
  const double sp = glm::length(s.c1);
  t = s.c1 / sp;
  const double c2t = glm::dot(s.c2, t);
  const Vec3d w = s.c2 - c2t * t;
  tv = w / sp;
  const Vec3d wv = s.c3 - (glm::dot(s.c3, t) + glm::dot(s.c2, tv)) * t - c2t * tv;
  tvv = wv / sp - tv * (c2t / sp);
}

}  // namespace

// ---- local differential geometry ----------------------------------------------------------------
TubeLocal tube_local_twisted(const CurveSample& s, const Vec3d& rho_in, double tau) {
  TubeLocal g;
  Vec3d tv, tvv;
  tangent_derivatives(s, g.t, tv, tvv);
  g.rho = glm::normalize(rho_in - glm::dot(rho_in, g.t) * g.t);
  g.b = glm::cross(g.t, g.rho);
  const Vec3d& rho = g.rho;
  const Vec3d& b = g.b;
  // rho_v has no component along b in a frame that does not twist; tau adds one (tests only).
  const Vec3d rho_v = -glm::dot(rho, tv) * g.t + tau * b;
  const Vec3d b_v = glm::cross(tv, rho) - tau * rho;
  const Vec3d rho_vv = -(glm::dot(rho_v, tv) + glm::dot(rho, tvv)) * g.t - glm::dot(rho, tv) * tv + tau * b_v;
  g.p = s.c + s.r * rho;
  g.mu = s.r * b;
  g.mv = s.c1 + s.r1 * rho + s.r * rho_v;
  g.muu = -s.r * rho;
  g.muv = s.r1 * b + s.r * b_v;
  g.mvv = s.c2 + s.r2 * rho + 2.0 * s.r1 * rho_v + s.r * rho_vv;
  const Vec3d nn = glm::cross(g.mu, g.mv);
  g.area_density = glm::length(nn);
  g.n = nn / g.area_density;
  g.E = glm::dot(g.mu, g.mu), g.F = glm::dot(g.mu, g.mv), g.G = glm::dot(g.mv, g.mv);
  g.L = -glm::dot(g.muu, g.n), g.M = -glm::dot(g.muv, g.n), g.N = -glm::dot(g.mvv, g.n);
  return g;
}

TubeLocal tube_local(const CurveSample& s, const Vec3d& rho) { return tube_local_twisted(s, rho, 0.0); }

void TubeLocal::shape_operator(double S[2][2]) const {
  const double det = E * G - F * F;
  const double i00 = G / det, i01 = -F / det, i11 = E / det;
  S[0][0] = i00 * L + i01 * M, S[0][1] = i00 * M + i01 * N;
  S[1][0] = i01 * L + i11 * M, S[1][1] = i01 * M + i11 * N;
}

namespace {
// Coordinates (x0, x1) of the tangent part of w in the basis (M_u, M_v): the full 2x2 system.
void tangent_coordinates(const TubeLocal& g, const Vec3d& w, double& x0, double& x1) {
  const Vec3d wt = w - glm::dot(w, g.n) * g.n;
  const double a = glm::dot(wt, g.mu), b = glm::dot(wt, g.mv), det = g.E * g.G - g.F * g.F;
  x0 = (g.G * a - g.F * b) / det;
  x1 = (g.E * b - g.F * a) / det;
}
}  // namespace

double TubeLocal::normal_curvature(const Vec3d& w) const {
  double x0, x1;
  tangent_coordinates(*this, w, x0, x1);
  const double ii = L * x0 * x0 + 2.0 * M * x0 * x1 + N * x1 * x1;
  const double i = E * x0 * x0 + 2.0 * F * x0 * x1 + G * x1 * x1;
  return ii / i;
}

double TubeLocal::shape_operator_norm(const Vec3d& w) const {
  double x0, x1, S[2][2];
  tangent_coordinates(*this, w, x0, x1);
  const double len = std::sqrt(E * x0 * x0 + 2.0 * F * x0 * x1 + G * x1 * x1);
  shape_operator(S);
  const double y0 = (S[0][0] * x0 + S[0][1] * x1) / len, y1 = (S[1][0] * x0 + S[1][1] * x1) / len;
  return glm::length(y0 * mu + y1 * mv);
}

void TubeLocal::normal_derivatives(Vec3d& nu, Vec3d& nv) const {
  double S[2][2];
  shape_operator(S);
  // Weingarten: n_k = sum_j S_jk M_j (II convex-positive, so the normal opens along a convex direction).
  nu = S[0][0] * mu + S[1][0] * mv;
  nv = S[0][1] * mu + S[1][1] * mv;
}

// ---- evaluation -----------------------------------------------------------------------------------
CurveSample BSplineCurve::eval(size_t s, double t) const { return eval_points(control_points.data(), span_first[s], t); }

void BSplineCurve::rest_frame(size_t s, double t, Vec3d& t_rest, Vec3d& n1_rest) const {
  // The rest RMF between table samples: the sample below t turned minimally to the rest tangent at t.
  const int j = std::clamp(int(std::floor(std::clamp(t, 0.0, 1.0) * kFrameSamples)), 0, kFrameSamples - 1);
  const size_t k = s * (kFrameSamples + 1) + size_t(j);
  t_rest = glm::normalize(eval_points(rest_points.data(), span_first[s], t).c1);
  n1_rest = rotate_min(frame_t[k], t_rest, frame_n1[k]);
}

Vec3d BSplineCurve::frame(size_t s, double t, const Vec3d& t_unit) const {
  Vec3d t_rest, n1_rest;
  rest_frame(s, t, t_rest, n1_rest);
  Vec3d n1 = rotate_min(t_rest, t_unit, n1_rest);
  n1 -= glm::dot(n1, t_unit) * t_unit;  // rounding only: the rotation keeps n1 perpendicular
  return glm::normalize(n1);
}

Vec3d BSplineCurve::radial(size_t s, double t, double u) const {
  const Vec3d tu = glm::normalize(eval(s, t).c1);
  const Vec3d n1 = frame(s, t, tu), n2 = glm::cross(tu, n1);
  return std::cos(u) * n1 + std::sin(u) * n2;
}

double BSplineCurve::angle_of(size_t s, double t, const Vec3d& rho) const {
  const Vec3d tu = glm::normalize(eval(s, t).c1);
  const Vec3d n1 = frame(s, t, tu), n2 = glm::cross(tu, n1);
  double u = std::atan2(glm::dot(rho, n2), glm::dot(rho, n1));
  if (u < 0.0) u += kTwoPi;
  return std::min(u, std::nextafter(kTwoPi, 0.0));
}

float BSplineCurve::curve_parameter(size_t s, double t) const {
  const uint32_t k = span_curve[s];
  return float((double(s - first_span(k)) + t) / double(spans_of(k)));
}

SilhouetteEquation BSplineCurve::silhouette_equation(size_t s, double t, const Vec3d& e, bool directional) const {
  // g(u) = (|C'| - r (k1 cos u + k2 sin u)) (d1 cos u + d2 sin u + h) - r' dT with (k1, k2) = T_v
  // in the frame, (d1, d2, dT) = C - e (or the direction) in (N1, N2, T), h = r (0 at infinity):
  // (M - e) . (M_u x M_v) / r expanded (docs/curves.md).
  const CurveSample cs = eval(s, t);
  Vec3d tu, tv, tvv;
  tangent_derivatives(cs, tu, tv, tvv);
  const Vec3d n1 = frame(s, t, tu), n2 = glm::cross(tu, n1);
  const Vec3d d = directional ? e : cs.c - e;
  const double sp = glm::length(cs.c1), r = cs.r, h = directional ? 0.0 : cs.r;
  const double k1 = glm::dot(n1, tv), k2 = glm::dot(n2, tv), d1 = glm::dot(d, n1), d2 = glm::dot(d, n2), dT = glm::dot(d, tu);
  SilhouetteEquation q;
  q.A = -r * (k1 * d1 - k2 * d2);
  q.B = -r * (k1 * d2 + k2 * d1);
  q.C = sp * d1 - r * h * k1;
  q.D = sp * d2 - r * h * k2;
  q.E = sp * h - r * k2 * d2 - cs.r1 * dT;
  q.front = std::atan2(-d2, -d1);
  // Constant radius: r' is then a rounding residue of the basis weights' sum (~1e-16 |C'|); the
  // first factor is positive below the radius limit, so the roots are those of the second.
  q.linear = std::abs(cs.r1) <= 1e-12 * sp;
  // Linear case: with r' = 0 the normal is rho and g / a = d1 cos u + d2 sin u + h.
  if (q.linear) q.A = q.B = 0.0, q.C = d1, q.D = d2, q.E = h;
  return q;
}

bool BSplineCurve::silhouette_root(const SilhouetteEquation& q, int side, int steps, double& u) {
  if (q.linear) {
    // d1 cos u + d2 sin u + h = 0: R cos(u - front) = h with R = |(d1, d2)|.
    const double R = std::hypot(q.C, q.D);
    if (!(R > std::abs(q.E))) return false;
    u = q.front + side * std::acos(q.E / R);
  } else {
    double a = q.front, b = q.front + side * M_PI;
    double ga = q.eval(a), gb = q.eval(b);
    if (!(ga < 0.0 && gb > 0.0)) return false;  // no sign change: no silhouette on this side
    for (int i = 0; i < steps; ++i) {
      const double m = 0.5 * (a + b), gm = q.eval(m);
      (gm < 0.0 ? a : b) = m;
      (gm < 0.0 ? ga : gb) = gm;
    }
    u = ga - gb != 0.0 ? a + (b - a) * ga / (ga - gb) : 0.5 * (a + b);  // secant inside the last bracket
  }
  u = std::fmod(u, kTwoPi);
  if (u < 0.0) u += kTwoPi;
  return true;
}

// ---- intersection -----------------------------------------------------------------------------------
bool BSplineCurve::refine_hit(size_t s, const Vec3d& o, const Vec3d& d, double& v, double& t) const {
  // Newton on F(v, t) = ((P - C) . C', |P - C|^2 - r^2), P = o + t d. Embree's float hit starts it
  // within ~1e-6 of the root; steps in v are limited to a quarter span.
  double r = 0.0;
  for (int it = 0; it < 16; ++it) {
    const CurveSample cs = eval(s, v);
    const Vec3d D = o + t * d - cs.c;
    r = cs.r;
    const double f1 = glm::dot(D, cs.c1), f2 = glm::dot(D, D) - cs.r * cs.r;
    const double j11 = -glm::dot(cs.c1, cs.c1) + glm::dot(D, cs.c2), j12 = glm::dot(d, cs.c1);
    const double j21 = -2.0 * glm::dot(D, cs.c1) - 2.0 * cs.r * cs.r1, j22 = 2.0 * glm::dot(D, d);
    const double det = j11 * j22 - j12 * j21;
    if (!(std::abs(det) > 0.0) || !std::isfinite(det)) return false;
    double dv = (f1 * j22 - f2 * j12) / det, dt = (j11 * f2 - j21 * f1) / det;
    const double cap = 0.25;
    if (std::abs(dv) > cap) {
      dt *= cap / std::abs(dv);
      dv = std::copysign(cap, dv);
    }
    v -= dv;
    t -= dt;
    if (!std::isfinite(v) || !std::isfinite(t)) return false;
    if (std::abs(dv) < 1e-13 && std::abs(dt) < 1e-13 * (std::abs(t) + cs.r)) break;
  }
  // Converged: on the cross-section circle to 1e-9 of the radius (double rounding of a unit-size
  // scene is ~1e-16; 1e-9 leaves room for coordinates at 1e4 with radii at 1e-4).
  const CurveSample cs = eval(s, v);
  const Vec3d D = o + t * d - cs.c;
  const double sp = glm::length(cs.c1);
  return std::abs(glm::length(D) - cs.r) <= 1e-9 * (cs.r + glm::length(cs.c)) && std::abs(glm::dot(D, cs.c1)) / sp <= 1e-9 * (r + glm::length(cs.c));
}

bool BSplineCurve::accept_hit(unsigned& s, const Vec3d& o, const Vec3d& d, float tnear, double& v, double& t, double& u, Vec3d& n) const {
  // A hit just past a joint belongs to the neighbouring span (1e-3: Embree's float parameter
  // there); past a curve's end there is no surface (open rims).
  for (int attempt = 0; attempt < 2; ++attempt) {
    if (!refine_hit(s, o, d, v, t)) return false;
    const uint32_t k = span_curve[s];
    if (v < 0.0) {
      if (s == first_span(k) || v < -1e-3) return false;
      --s, v += 1.0;
    } else if (v > 1.0) {
      if (s + 1 == first_span(k) + spans_of(k) || v > 1.0 + 1e-3) return false;
      ++s, v -= 1.0;
    } else {
      break;
    }
  }
  if (v < 0.0 || v > 1.0 || !(t > double(tnear))) return false;
  const CurveSample cs = eval(s, v);
  Vec3d tu, tv, tvv;
  tangent_derivatives(cs, tu, tv, tvv);
  Vec3d rho = o + t * d - cs.c;
  rho = glm::normalize(rho - glm::dot(rho, tu) * tu);
  // The true normal: M_u x M_v ~ (|C'| - r rho . T_v) rho - r' T (Embree's drops the curvature factor).
  n = glm::normalize((glm::length(cs.c1) - cs.r * glm::dot(rho, tv)) * rho - cs.r1 * tu);
  if (!(glm::dot(n, d) < 0.0)) return false;  // seen from inside: the surface is one-sided
  u = angle_of(s, v, rho);
  return true;
}

namespace {

template <bool kOcclusion>
void curve_filter(const RTCFilterFunctionNArguments* args) {
  const BSplineCurve& c = *static_cast<const BSplineCurve*>(args->geometryUserPtr);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    RTCRayN* ray = args->ray;
    RTCHitN* hit = args->hit;
    const Vec3d o(RTCRayN_org_x(ray, args->N, i), RTCRayN_org_y(ray, args->N, i), RTCRayN_org_z(ray, args->N, i));
    const Vec3d d(RTCRayN_dir_x(ray, args->N, i), RTCRayN_dir_y(ray, args->N, i), RTCRayN_dir_z(ray, args->N, i));
    unsigned s = RTCHitN_primID(hit, args->N, i);
    double v = RTCHitN_u(hit, args->N, i), t = RTCRayN_tfar(ray, args->N, i), u;
    Vec3d n;
    if (s >= c.span_count() || !c.accept_hit(s, o, d, RTCRayN_tnear(ray, args->N, i), v, t, u, n)) {
      args->valid[i] = 0;
      continue;
    }
    if (kOcclusion) continue;
    // The refined hit for fill_hit: span, v on it, u / 2 pi, the true normal.
    RTCHitN_primID(hit, args->N, i) = s;
    RTCHitN_u(hit, args->N, i) = float(v);
    RTCHitN_v(hit, args->N, i) = float(u / kTwoPi);
    RTCHitN_Ng_x(hit, args->N, i) = float(n.x);
    RTCHitN_Ng_y(hit, args->N, i) = float(n.y);
    RTCHitN_Ng_z(hit, args->N, i) = float(n.z);
    if (float(t) < RTCRayN_tfar(ray, args->N, i)) RTCRayN_tfar(ray, args->N, i) = float(t);  // Embree allows decreasing only
  }
}

}  // namespace

void BSplineCurve::fill_hit(const Ray& ray, float, unsigned prim, const Vec2& uv, SurfaceInteraction& si) const {
  const size_t s = std::min<size_t>(prim, span_count() - 1);
  const double v = std::clamp(double(uv.x), 0.0, 1.0), u = double(uv.y) * kTwoPi;
  const CurveSample cs = eval(s, v);
  Vec3d tu, tv, tvv;
  tangent_derivatives(cs, tu, tv, tvv);
  const Vec3d n1 = frame(s, v, tu), rho = std::cos(u) * n1 + std::sin(u) * glm::cross(tu, n1);
  const Vec3d p = cs.c + cs.r * rho;
  const Vec3d n = glm::normalize((glm::length(cs.c1) - cs.r * glm::dot(rho, tv)) * rho - cs.r1 * tu);
  si.p = Vec3(p);
  si.t = float(glm::dot(p - Vec3d(ray.o), Vec3d(ray.d)));
  // p is exact in double and rounded once; 5 ulps of its magnitude and the radius (as spheres).
  si.p_error = gamma_bound(5) * (glm::abs(si.p) + Vec3(float(cs.r)));
  si.ng = si.ns = Vec3(n);
  si.uv = Vec2(curve_parameter(s, v), uv.y);
  si.bary = Vec2(float(v), uv.y);
  si.prim = int(s);
  si.frame = Frame(si.ns);
}

RTCGeometry BSplineCurve::create_embree_geometry(RTCDevice device) const {
  RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_ROUND_BSPLINE_CURVE);
  rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 4 * sizeof(float), point_count());
  auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT, sizeof(uint32_t), span_count()));
  if (idx) std::memcpy(idx, span_first.data(), span_first.size() * sizeof(uint32_t));
  rtcSetGeometryUserData(g, const_cast<BSplineCurve*>(this));
  rtcSetGeometryIntersectFilterFunction(g, curve_filter<false>);
  rtcSetGeometryOccludedFilterFunction(g, curve_filter<true>);
  update_embree_geometry(g);
  return g;
}

void BSplineCurve::update_embree_geometry(RTCGeometry g) const {
  auto* v = static_cast<float*>(rtcGetGeometryBufferData(g, RTC_BUFFER_TYPE_VERTEX, 0));
  if (!v) return;  // Embree reported the error through its callback
  std::memcpy(v, control_points.data(), control_points.size() * sizeof(float));
  rtcUpdateGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0);
}

// ---- derived state ------------------------------------------------------------------------------------
void BSplineCurve::build_derived() {
  span_first.clear();
  span_curve.clear();
  for (size_t k = 0; k < curve_count(); ++k)
    for (uint32_t i = curve_offsets[k]; i + 3 < curve_offsets[k + 1]; ++i) {
      span_first.push_back(i);
      span_curve.push_back(uint32_t(k));
    }
  const size_t S = span_count();
  // Rotation-minimising frame along each curve: N1 carried from sample to sample by the minimal
  // rotation between consecutive unit tangents (the "rotation method"; O(h^2) from the exact RMF,
  // continuous across joints because a span's first entry is the previous span's last, rotated
  // by the identity). Built on a rest copy of the points, refreshed only when needed (curve.h).
  bool refresh = rest_points.size() != control_points.size() || frame_n1.size() != S * (kFrameSamples + 1);
  for (size_t s = 0; s < S && !refresh; ++s)
    for (int j = 0; j <= 4 * kFrameSamples && !refresh; ++j) {
      const double t = double(j) / (4 * kFrameSamples);
      const Vec3d a = glm::normalize(eval_points(rest_points.data(), span_first[s], t).c1), b = glm::normalize(eval(s, t).c1);
      refresh = !(glm::dot(a, b) > 0.5);  // 60 degrees: far from the minimal rotation's singularity at 180
    }
  if (refresh) {
    rest_points = control_points;
    frame_n1.assign(S * (kFrameSamples + 1), Vec3d(0.0));
    frame_t.assign(S * (kFrameSamples + 1), Vec3d(0.0));
    for (size_t k = 0; k < curve_count(); ++k) {
      Vec3d t_prev(0.0), n1(0.0);
      for (uint32_t s = first_span(k); s < first_span(k) + spans_of(k); ++s)
        for (int j = 0; j <= kFrameSamples; ++j) {
          const Vec3d tj = glm::normalize(eval(s, double(j) / kFrameSamples).c1);
          if (s == first_span(k) && j == 0) n1 = any_perpendicular(tj);
          else n1 = rotate_min(t_prev, tj, n1);
          n1 = glm::normalize(n1 - glm::dot(n1, tj) * tj);
          frame_n1[size_t(s) * (kFrameSamples + 1) + size_t(j)] = n1;
          frame_t[size_t(s) * (kFrameSamples + 1) + size_t(j)] = tj;
          t_prev = tj;
        }
    }
  }
  // Areas per bin: 4-point Gauss-Legendre in t, 16 points around (periodic trapezoid, spectrally
  // accurate) of |M_u x M_v| = r sqrt((|C'| - r |T_v| cos u)^2 + r'^2).
  static const double gx[4] = {-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526};
  static const double gw[4] = {0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538};
  bin_area.assign(S * kBins, 0.0);
  std::vector<float> weights(S * kBins);
  span_lo.assign(S, Vec3(kInfinity));
  span_hi.assign(S, Vec3(-kInfinity));
  total_area = 0.0;
  for (size_t s = 0; s < S; ++s) {
    for (int k = 0; k < 4; ++k) {
      const Vec3 p = point(span_first[s] + uint32_t(k));
      const float r = control_points[4 * (span_first[s] + uint32_t(k)) + 3];
      span_lo[s] = glm::min(span_lo[s], p - Vec3(r));  // the convex hull holds C; r(v) <= max r
      span_hi[s] = glm::max(span_hi[s], p + Vec3(r));
    }
    for (int bi = 0; bi < kBins; ++bi) {
      double a = 0.0;
      for (int q = 0; q < 4; ++q) {
        const double t = (bi + 0.5 + 0.5 * gx[q]) / kBins;
        const CurveSample cs = eval(s, t);
        Vec3d tu, tv, tvv;
        tangent_derivatives(cs, tu, tv, tvv);
        const double sp = glm::length(cs.c1), kr = cs.r * glm::length(tv);
        double ring = 0.0;
        for (int m = 0; m < 16; ++m) ring += std::hypot(sp - kr * std::cos(kTwoPi * m / 16), cs.r1);
        a += gw[q] * 0.5 / kBins * cs.r * ring * (kTwoPi / 16);
      }
      bin_area[s * kBins + size_t(bi)] = a;
      total_area += a;
      weights[s * kBins + size_t(bi)] = float(a / eval(s, (bi + 0.5) / kBins).r);
    }
  }
  if (!weights.empty()) bins = Distribution1D(weights);
}

std::string BSplineCurve::check(const float* cps) const {
  std::ostringstream msg;
  for (size_t k = 0; k < curve_count(); ++k) {
    const uint32_t a = curve_offsets[k], b = curve_offsets[k + 1];
    if (b - a < 4) {
      msg << "curve " << k << " has " << (b - a) << " control point(s); a cubic B-spline needs at least 4";
      return msg.str();
    }
    for (uint32_t i = a; i < b; ++i) {
      const float* q = cps + 4 * size_t(i);
      if (!(std::isfinite(q[0]) && std::isfinite(q[1]) && std::isfinite(q[2]) && std::isfinite(q[3]))) {
        msg << "curve " << k << ", control point " << i << " is not finite (" << format_values(q, 4) << ")";
        return msg.str();
      }
      if (!(q[3] > 0.0f)) {
        msg << "curve " << k << ", control point " << i << ": radius must be > 0 (got " << q[3] << ")";
        return msg.str();
      }
      if (std::abs(q[0]) + q[3] > kMaxCoordinate || std::abs(q[1]) + q[3] > kMaxCoordinate || std::abs(q[2]) + q[3] > kMaxCoordinate) {
        msg << "curve " << k << ", control point " << i << " (" << format_values(q, 4) << ") reaches beyond the traceable range (|coordinate| <= 1e18)";
        return msg.str();
      }
    }
    for (uint32_t first = a; first + 3 < b; ++first) {
      double size = 0.0;
      for (int m = 1; m < 4; ++m)
        for (int c = 0; c < 3; ++c) size = std::max(size, std::abs(double(cps[4 * (first + m) + c]) - cps[4 * first + c]));
      for (int j = 0; j <= kCheckSamples; ++j) {
        const double t = double(j) / kCheckSamples;
        const CurveSample cs = eval_points(cps, first, t);
        const uint32_t nearest = first + (t < 0.5 ? 1u : 2u);  // the point with the largest basis weight
        const double sp = glm::length(cs.c1);
        // Zero length: |C'| below 1e-6 of the span's extent (float control points resolve ~1e-7).
        if (!(sp > 1e-6 * size)) {
          msg << "curve " << k << ": the span of control points " << first << ".." << first + 3
              << " has zero length near control point " << nearest << " (|C'| = " << sp
              << "; repeated or collinear-doubling control points make a cusp); remove the repeated point";
          return msg.str();
        }
        const double kappa = glm::length(glm::cross(cs.c1, cs.c2)) / (sp * sp * sp);
        if (!(cs.r * kappa < 1.0)) {
          msg << "curve " << k << ": near control point " << nearest << " the radius " << cs.r
              << " exceeds the curvature radius " << (kappa > 0 ? 1.0 / kappa : kInfinity)
              << " of the centre line (the tube would fold); use a smaller radius or a gentler bend";
          return msg.str();
        }
      }
    }
  }
  return "";
}

// ---- parameters ---------------------------------------------------------------------------------------
void BSplineCurve::list_parameters(const std::string& id, int index, std::vector<Parameter>& out) {
  out.push_back({id + ".control_points", Parameter::Kind::CurveControlPoints, index, control_points.data(), {point_count(), 4}, true});
}

void BSplineCurve::validate_parameter(const Parameter& p, const std::string& where) const {
  const std::string problem = check(p.data);
  if (!problem.empty()) throw std::invalid_argument(where + ": " + problem);
}

void BSplineCurve::translate(const Vec3& delta) {
  for (size_t i = 0; i < point_count(); ++i)
    for (int c = 0; c < 3; ++c) control_points[4 * i + c] += delta[c];
  build_derived();
}

void BSplineCurve::bounds(Vec3& lo, Vec3& hi) const {
  lo = Vec3(kInfinity);
  hi = Vec3(-kInfinity);
  for (size_t i = 0; i < point_count(); ++i) {
    lo = glm::min(lo, point(i) - Vec3(control_points[4 * i + 3]));
    hi = glm::max(hi, point(i) + Vec3(control_points[4 * i + 3]));
  }
}

void BSplineCurve::geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const {
  values.insert(values.end(), control_points.begin(), control_points.end());
  Vec3 l, h;
  bounds(l, h);
  lo = glm::min(lo, l);
  hi = glm::max(hi, h);
}

}  // namespace limn
