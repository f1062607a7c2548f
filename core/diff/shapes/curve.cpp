#include "core/diff/shapes/curve.h"

#include "core/math/warp.h"

namespace limn {
namespace {

using ad::Var;
using VV = ad::V3<Var>;
constexpr double kTwoPi = 2.0 * M_PI;

const BSplineCurve& curve_of(const Scene& scene, int shape) { return std::get<BSplineCurve>(scene.shapes[shape].geometry); }
VV constant(const Vec3d& v) { return VV(Var(v.x), Var(v.y), Var(v.z)); }
Vec3d vec3d(const ad::V3<double>& v) { return Vec3d(v.x, v.y, v.z); }
ad::V3<double> v3d(const Vec3d& v) { return ad::V3<double>(v.x, v.y, v.z); }

// C, C', C'', r, r' of a span on the tape.
struct SpanTape {
  VV c, c1, c2;
  Var r, r1;
};
SpanTape span_tape(const DiffContext& ctx, const BSplineCurve& g, int shape, size_t span, double t) {
  const double s = 1.0 - t, t2 = t * t, t3 = t2 * t;
  const double w[4] = {s * s * s / 6.0, (3 * t3 - 6 * t2 + 4) / 6.0, (-3 * t3 + 3 * t2 + 3 * t + 1) / 6.0, t3 / 6.0};
  const double w1[4] = {-0.5 * s * s, 0.5 * (3 * t2 - 4 * t), 0.5 * (-3 * t2 + 2 * t + 1), 0.5 * t2};
  const double w2[4] = {s, 3 * t - 2, -3 * t + 1, t};
  SpanTape st;
  for (int k = 0; k < 4; ++k) {
    VV p;
    Var r;
    curve_point(ctx, shape, g.span_first[span] + uint32_t(k), p, r);
    st.c = st.c + p * Var(w[k]);
    st.c1 = st.c1 + p * Var(w1[k]);
    st.c2 = st.c2 + p * Var(w2[k]);
    st.r = st.r + r * Var(w[k]);
    st.r1 = st.r1 + r * Var(w1[k]);
  }
  return st;
}

// rho on the tape, as the primal frame computes it (BSplineCurve::frame): the rest radial
// direction turned by the minimal rotation from the rest tangent to the moved unit tangent T.
// rho0 is the primal rho (at T0); the rest one is its inverse rotation.
VV radial_tape(const BSplineCurve& g, size_t span, double t, const VV& T, const Vec3d& rho0) {
  Vec3d t_rest, n1_rest;
  g.rest_frame(span, t, t_rest, n1_rest);
  const Vec3d T0 = glm::normalize(g.eval(span, t).c1);
  const Vec3d rho_rest = rotate_min(T0, t_rest, rho0);
  // rotate_min(a, b, x) = x - (a + b) ((a + b) . x) / (1 + a . b) + 2 (a . x) b, with b = T on the tape.
  const VV a = constant(t_rest), x = constant(rho_rest), ab = a + T;
  return x - ab * (dot(ab, x) / (Var(1.0) + dot(a, T))) + T * Var(2.0 * glm::dot(t_rest, rho_rest));
}

// ---- boundary points ------------------------------------------------------------------------------
void set_param(BoundaryPoint& out, size_t span, double t, double u) { out.param = Vec3(float(span), float(t), float(u / kTwoPi)); }

// x_b on the tube at (span, t, u) with tangential direction w (interior part of Eq. 4).
bool finish_interior(const TubeLocal& L, size_t span, double t, double u, double r, const Vec3d& w, BoundaryPoint& out) {
  out.xb = Vec3(L.p);
  out.w = Vec3(w);
  out.n_b = out.n_out = Vec3(L.n);  // growing along n covers the background
  out.delta = probe_offset(float(r), out.xb);
  set_param(out, span, t, u);
  const double kappa = L.normal_curvature(w);
  out.jacobian = float(kappa);
  // kappa <= 0: the line along w enters the tube beside x_b on both sides (inside of a bend), so
  // nothing changes visibility there.
  return kappa > 0.0 && std::isfinite(kappa);
}

// x_b on a rim (end 0: v = 0 of the curve, 1: its end) with direction w (perimeter part of Eq. 4).
bool finish_rim(const TubeLocal& L, int end, size_t span, double t, double u, double r, const Vec3d& w, BoundaryPoint& out) {
  out.xb = Vec3(L.p);
  out.w = Vec3(w);
  set_param(out, span, t, u);
  out.delta = probe_offset(float(r), out.xb);
  out.n_out = Vec3(L.n);
  const Vec3d txw = glm::cross(L.b, w);
  const double sin_phi = glm::length(txw);
  out.jacobian = float(sin_phi);
  if (!(glm::dot(w, L.n) > 0.0)) return false;  // from inside: the one-sided surface blocks nothing there
  if (!(sin_phi > 1e-6)) return false;           // w along the rim: the rim is invisible in that direction
  // The tube lies on the side of the surface direction into it (M_v without its rim component).
  Vec3d into = L.mv - glm::dot(L.mv, L.b) * L.b;
  into = glm::normalize(into) * (end == 0 ? 1.0 : -1.0);
  const Vec3d s = txw / sin_phi;
  const double side = glm::dot(s, into);
  if (!(std::abs(side) > 1e-6)) return false;  // w in the tangent plane: edge-on
  out.n_b = Vec3(side > 0.0 ? -s : s);         // away from the occluder
  return true;
}

void rim_of(const BSplineCurve& g, int rim, size_t& span, double& t, int& end) {
  const size_t k = size_t(rim / 2);
  end = rim % 2;
  span = end == 0 ? g.first_span(k) : g.first_span(k) + g.spans_of(k) - 1;
  t = end == 0 ? 0.0 : 1.0;
}

// The interior bin of f: span, t.
void interior_coordinate(const BSplineCurve& g, float f, size_t& bin, double& offset, size_t& span, double& t) {
  offset = g.bins.sample_remapped(f, &bin);
  span = bin / BSplineCurve::kBins;
  t = (double(bin % BSplineCurve::kBins) + offset) / BSplineCurve::kBins;
}

// dX/dt along the silhouette X(t) = M(u*(t), t) seen from e (or along direction e), by implicit
// differentiation of g = (M - e) . n (n . e for a direction): du/dt = -g_t / g_u.
Vec3d silhouette_tangent(const TubeLocal& L, const Vec3d& e, bool directional) {
  Vec3d nu, nv;
  L.normal_derivatives(nu, nv);
  const Vec3d d = directional ? e : L.p - e;
  const double gu = glm::dot(d, nu), gt = glm::dot(d, nv);
  if (!(std::abs(gu) > 0.0)) return Vec3d(0.0);
  return L.mv - (gt / gu) * L.mu;
}

// The root of the silhouette equation at (span, t) on `side` seen from e (or along e).
bool silhouette_at(const BSplineCurve& g, size_t span, double t, const Vec3d& e, bool directional, int side, int steps, double& u) {
  return BSplineCurve::silhouette_root(g.silhouette_equation(span, t, e, directional), side, steps, u);
}

// ---- projection -----------------------------------------------------------------------------------
// At fixed v the silhouette seen from x_a solves the paper's A cos^2 u + B cos u sin u + C cos u +
// D sin u + E = 0 (closed form for constant radius; 20 bisection steps otherwise); the root on the
// hit's side of the tube is taken. Hits on a curve's end span go, half of the time, to the nearer
// rim (a boundary for every direction on its outer side). When no root brackets (x_a inside the
// cross-section's cylinder) the projection fails: it snaps to the nearer rim, found = false.
class CurveProjector : public ShapeProjector {
 public:
  CurveProjector(const BSplineCurve& g, const SegmentSpace& space, const std::vector<int>& segments) : m_curve(g), m_space(space) {
    m_rim_segment.assign(2 * g.curve_count(), -1);
    for (int seg : segments) {
      const BoundarySegment& s = space.segments()[size_t(seg)];
      if (s.part == BoundaryPart::Interior) m_interior = seg;
      else m_rim_segment[size_t(s.local)] = seg;
    }
  }

  std::optional<Projection> project(const Vec3& xa, const SurfaceInteraction& hit, Pcg32& rng) const override {
    const BSplineCurve& g = m_curve;
    const size_t span = size_t(hit.prim);
    const double t = hit.bary.x, u_hit = kTwoPi * hit.bary.y;
    const uint32_t k = g.span_curve[span];
    const bool first = span == g.first_span(k), last = span + 1 == size_t(g.first_span(k) + g.spans_of(k));
    const int near_end = first && last ? (t < 0.5 ? 0 : 1) : (first ? 0 : 1);
    if ((first || last) && rng.next_float() < 0.5f) {
      if (auto p = rim(k, near_end, u_hit, xa, true)) return p;
    }
    if (m_interior >= 0) {
      const SilhouetteEquation q = g.silhouette_equation(span, t, Vec3d(xa), false);
      double best = 0.0, best_dist = kInfinity;
      for (int side : {-1, 1}) {
        double u;
        if (!BSplineCurve::silhouette_root(q, side, 20, u)) continue;
        const double dist = std::abs(std::remainder(u - u_hit, kTwoPi));
        if (dist < best_dist) best = u, best_dist = dist;
      }
      if (best_dist < kInfinity) {
        const TubeLocal L = g.local(span, t, best);
        const Vec3 xb(L.p), w_orig = glm::normalize(xa - hit.p), n(L.n);
        if (auto p = finish_projection(m_space, m_interior, xa, xb, true, w_orig - glm::dot(w_orig, n) * n)) return p;
      }
    }
    return rim(k, first || last ? near_end : (t < 0.5 ? 0 : 1), u_hit, xa, false);  // failed: the nearer rim
  }

 private:
  std::optional<Projection> rim(uint32_t k, int end, double u, const Vec3& xa, bool found) const {
    const int seg = m_rim_segment[2 * size_t(k) + size_t(end)];
    if (seg < 0) return std::nullopt;
    size_t span;
    double t;
    int e;
    rim_of(m_curve, int(2 * k) + end, span, t, e);
    const Vec3 xb(m_curve.local(span, t, u).p);
    return finish_projection(m_space, seg, xa, xb, found, xa - xb);
  }

  const BSplineCurve& m_curve;
  const SegmentSpace& m_space;
  int m_interior = -1;
  std::vector<int> m_rim_segment;  // by rim: its segment in the space, -1 if none
};

}  // namespace

// ---- tape -------------------------------------------------------------------------------------------
void curve_point(const DiffContext& c, int shape, uint32_t i, VV& p, Var& r) {
  const BSplineCurve& g = curve_of(c.scene, shape);
  const long slot = c.params.slot(Parameter::Kind::CurveControlPoints, shape);
  const long base = slot < 0 ? -1 : slot + 4 * long(i);
  const float* q = &g.control_points[4 * size_t(i)];
  p = plus_translation(c.params, c.in, shape,
                       VV(c.in.make(q[0], base), c.in.make(q[1], base < 0 ? -1 : base + 1), c.in.make(q[2], base < 0 ? -1 : base + 2)));
  r = c.in.make(q[3], base < 0 ? -1 : base + 3);
}

VV curve_position(const DiffContext& c, const BSplineCurve& g, int shape, size_t span, double t, const Vec3d& rho0) {
  const SpanTape st = span_tape(c, g, shape, span, t);
  return st.c + radial_tape(g, span, t, normalize(st.c1), rho0) * st.r;
}

VV SurfaceDiff<BSplineCurve>::position(const DiffContext& c, const BSplineCurve& g, const SurfacePoint& sp) {
  const size_t span = size_t(sp.prim);
  const double t = sp.bary.x;
  return curve_position(c, g, sp.shape, span, t, g.radial(span, t, kTwoPi * sp.bary.y));
}

DiffVertex SurfaceDiff<BSplineCurve>::attach(const DiffContext& c, const BSplineCurve& g, const SurfacePoint& sp) {
  const size_t span = size_t(sp.prim);
  const double t = sp.bary.x;
  const SpanTape st = span_tape(c, g, sp.shape, span, t);
  const Var speed = length(st.c1);
  const VV T = st.c1 / speed;
  const VV rho = radial_tape(g, span, t, T, g.radial(span, t, kTwoPi * sp.bary.y));
  DiffVertex x;
  x.p = st.c + rho * st.r;
  // M_u x M_v = r (a rho - r' T), a = |C'| - r rho . T_v, T_v = C''_perp / |C'| (docs/curves.md).
  const VV tv = (st.c2 - T * dot(st.c2, T)) / speed;
  const Var a = speed - st.r * dot(rho, tv);
  x.ng = x.ns = normalize(rho * a - T * st.r1);
  const Var density = st.r * sqrt(a * a + st.r1 * st.r1);
  x.jacobian = density / Var(density.v);
  x.u = Var(sp.uv.x);
  x.v = Var(sp.uv.y);
  return x;
}

DiffVertex SurfaceDiff<BSplineCurve>::ray_hit(const DiffContext& c, const BSplineCurve& g, const VV& o, const VV& d,
                                              const SurfaceInteraction& si, const Ray&) {
  // The hit slides over the surface: first order in theta, the ray meets the tangent plane of the
  // attached point, t = (M - o) . n0 / (d . n0); the normal turns by the Weingarten map along the
  // slide (M_u du + M_v dv = the hit's offset from the attached point).
  const size_t span = size_t(si.prim);
  const double t0 = si.bary.x, u0 = kTwoPi * si.bary.y;
  const TubeLocal L = g.local(span, t0, u0);
  const DiffVertex att = attach(c, g, SurfacePoint::of(si));
  const VV n0 = constant(L.n);
  const Var t = dot(att.p - o, n0) / dot(d, n0);
  DiffVertex x;
  x.p = o + d * t;
  const VV off = x.p - att.p;
  const double det = L.E * L.G - L.F * L.F;
  const Var a = dot(off, constant(L.mu)), b = dot(off, constant(L.mv));
  const Var du = (a * Var(L.G) - b * Var(L.F)) / Var(det), dv = (b * Var(L.E) - a * Var(L.F)) / Var(det);
  Vec3d nu, nv;
  L.normal_derivatives(nu, nv);
  x.ng = x.ns = normalize(att.ng + constant(nu) * du + constant(nv) * dv);
  // Texture coordinates: u / 2 pi around, the curve parameter along (spans of equal share).
  const uint32_t k = g.span_curve[span];
  x.u = att.u + dv / Var(double(g.spans_of(k)));
  x.v = att.v + du / Var(kTwoPi);
  return x;
}

// ---- boundary segments --------------------------------------------------------------------------------
void BoundarySegments<BSplineCurve>::append(const Scene&, const BSplineCurve& g, int shape, bool moving, BoundaryPart part,
                                            std::vector<BoundarySegment>& out) {
  if (part == BoundaryPart::Interior) {
    // Weight: the measure (2 pi area) times a typical curvature (1 / r per bin).
    const float measure = float(kTwoPi * g.total_area);
    out.push_back({shape, 0, measure, float(kTwoPi * g.bins.integral() * double(g.bins.size())), moving, part});
    return;
  }
  for (int rim = 0; rim < int(2 * g.curve_count()); ++rim) {
    size_t span;
    double t;
    int end;
    rim_of(g, rim, span, t, end);
    const float measure = float(kTwoPi * g.eval(span, t).r * kTwoPi);  // rim length x the outer hemisphere
    out.push_back({shape, rim, measure, measure, moving, part});
  }
}

bool BoundarySegments<BSplineCurve>::sample(const Scene&, const BSplineCurve& g, const BoundarySegment& seg, float f, float u1, float u2,
                                            float pdf_select, BoundaryPoint& out) {
  if (seg.part == BoundaryPart::Interior) {
    size_t bin, span;
    double offset, t;
    interior_coordinate(g, f, bin, offset, span, t);
    const double u = kTwoPi * u1, phi = kTwoPi * u2;
    const CurveSample cs = g.eval(span, t);
    const TubeLocal L = tube_local(cs, g.radial(span, t, u));  // g.local(span, t, u) with cs kept for r
    const Vec3d e2 = glm::cross(L.n, L.b);
    // Density over (t, u, phi): pmf(bin) kBins / (2 pi)^2; per dA dphi divided by |M_u x M_v|.
    out.pdf = float(pdf_select * g.bins.pmf(bin) * BSplineCurve::kBins / (kTwoPi * kTwoPi * L.area_density));
    return finish_interior(L, span, t, u, cs.r, std::cos(phi) * L.b + std::sin(phi) * e2, out);
  }
  size_t span;
  double t;
  int end;
  rim_of(g, seg.local, span, t, end);
  const double u = kTwoPi * f;
  const TubeLocal L = g.local(span, t, u);
  const double r = g.eval(span, t).r;
  const Vec3 w = Frame(Vec3(L.n)).to_world(warp::square_to_uniform_hemisphere(Vec2(u1, u2)));
  out.pdf = float(pdf_select / (kTwoPi * r) / kTwoPi);
  return finish_rim(L, end, span, t, u, r, glm::normalize(Vec3d(w)), out);
}

Vec3 BoundarySegments<BSplineCurve>::invert(const Scene&, const BSplineCurve& g, const BoundarySegment& seg, const Vec3& xb, const Vec3& w) {
  auto wrap = [](double x) { return float(std::clamp(x - std::floor(x), 0.0, double(std::nextafter(1.0f, 0.0f)))); };
  if (seg.part == BoundaryPart::Interior) {
    size_t span;
    double t, u;
    if (!curve_locate(g, xb, span, t, u)) return Vec3(0.0f);
    const size_t b = std::min<size_t>(size_t(t * BSplineCurve::kBins), BSplineCurve::kBins - 1);
    const double offset = std::clamp(t * BSplineCurve::kBins - double(b), 0.0, 1.0);
    const TubeLocal L = g.local(span, t, u);
    const Vec3d wd(w), e2 = glm::cross(L.n, L.b);
    const double phi = std::atan2(glm::dot(wd, e2), glm::dot(wd, L.b));
    return Vec3(g.bins.invert_remapped(span * BSplineCurve::kBins + b, float(offset)), wrap(u / kTwoPi), wrap(phi / kTwoPi));
  }
  size_t span;
  double t;
  int end;
  rim_of(g, seg.local, span, t, end);
  const CurveSample cs = g.eval(span, t);
  const double u = g.angle_of(span, t, Vec3d(xb) - cs.c);
  const TubeLocal L = g.local(span, t, u);
  const Vec3 local = Frame(Vec3(L.n)).to_local(w);
  return Vec3(wrap(u / kTwoPi), wrap(std::atan2(double(local.y), double(local.x)) / kTwoPi),
              std::clamp(local.z, 0.0f, std::nextafter(1.0f, 0.0f)));
}

bool BoundarySegments<BSplineCurve>::sample_delta(const Scene&, const BSplineCurve& g, const BoundarySegment& seg, float f, float pdf_select,
                                                  const Emitter& light, BoundaryPoint& out) {
  const auto* point = std::get_if<PointEmitter>(&light.model);
  const auto* directional = std::get_if<DirectionalEmitter>(&light.model);
  if (!point && !directional) return false;
  const Vec3d e = point ? Vec3d(point->position) : Vec3d(glm::normalize(directional->direction));
  if (seg.part == BoundaryPart::Interior) {
    // u.x: a bin, then the side of the tube (first or second half of the bin's share), then t.
    size_t bin, span;
    double offset, t;
    interior_coordinate(g, f, bin, offset, span, t);
    const int side = offset < 0.5 ? -1 : 1;
    const double o2 = offset < 0.5 ? 2.0 * offset : 2.0 * offset - 1.0;
    t = (double(bin % BSplineCurve::kBins) + o2) / BSplineCurve::kBins;
    double u;
    // 50 halvings of pi: below double resolution of the angle (the delta term needs the exact curve).
    if (!silhouette_at(g, span, t, e, !point, side, 50, u)) return false;
    const TubeLocal L = g.local(span, t, u);
    const Vec3d w = point ? glm::normalize(L.p - e) : e;
    if (!finish_interior(L, span, t, u, g.eval(span, t).r, w, out)) return false;
    // Eq. 4's inner integral with a Dirac in w: kappa_n(w) / |S w| per unit length of the curve
    // where w grazes (docs/curves.md; 1 on a sphere).
    const double snorm = L.shape_operator_norm(w);
    const double speed = glm::length(silhouette_tangent(L, e, !point));
    if (!(snorm > 0.0) || !(speed > 0.0)) return false;
    out.jacobian = float(L.normal_curvature(w) / snorm);
    out.pdf = float(pdf_select * g.bins.pmf(bin) * BSplineCurve::kBins * 0.5 / speed);
    return out.pdf > 0.0f && std::isfinite(out.pdf) && std::isfinite(out.jacobian);
  }
  size_t span;
  double t;
  int end;
  rim_of(g, seg.local, span, t, end);
  const double u = kTwoPi * f, r = g.eval(span, t).r;
  const TubeLocal L = g.local(span, t, u);
  const Vec3d wl = point ? L.p - e : e;
  if (!(glm::length(wl) > 0.0) || !finish_rim(L, end, span, t, u, r, glm::normalize(wl), out)) return false;
  out.pdf = float(pdf_select / (kTwoPi * r));
  return true;
}

VV BoundarySegments<BSplineCurve>::attached_point(const DiffContext& c, const BSplineCurve& g, const BoundarySegment& seg,
                                                  const BoundaryPoint& p) {
  const size_t span = size_t(p.param.x);
  return curve_position(c, g, seg.shape, span, p.param.y, g.radial(span, p.param.y, kTwoPi * p.param.z));
}

std::unique_ptr<ShapeProjector> BoundarySegments<BSplineCurve>::projector(const Scene&, const BSplineCurve& g, const SegmentSpace& space, int,
                                                                          const std::vector<int>& segments, MeshProjection) {
  return std::make_unique<CurveProjector>(g, space, segments);
}

// ---- camera silhouettes ---------------------------------------------------------------------------------
void CameraSilhouettes<BSplineCurve>::append(const Scene&, const BSplineCurve& g, int shape, const CameraView& view,
                                             std::vector<SilhouetteCurve>& out, uint64_t& skipped) {
  const Vec3d eye = vec3d(view.eye);
  const size_t S = g.span_count();
  // Selection weight: projected length in pixels from 9 points per span side; a side without a
  // silhouette at those points keeps a small weight (it may have one between them).
  for (size_t s = 0; s < S; ++s)
    for (int side : {-1, 1}) {
      double len = 0.0;
      glm::dvec2 prev(0.0);
      bool have_prev = false, behind = false;
      for (int j = 0; j <= 8; ++j) {
        const double t = j / 8.0;
        double u;
        glm::dvec2 cur(0.0);
        if (!silhouette_at(g, s, t, eye, false, side, 30, u)) {
          have_prev = false;
          continue;
        }
        if (!view.film_of(v3d(g.local(s, t, u).p), cur)) {
          behind = true;
          break;
        }
        if (have_prev) len += glm::length(cur - prev);
        prev = cur, have_prev = true;
      }
      if (behind) {
        ++skipped;  // limitation: silhouettes crossing the near plane are skipped (and counted), as mesh edges
        continue;
      }
      out.push_back({shape, int(2 * s + (side > 0 ? 1 : 0)), float(std::max(len, 1e-2))});
    }
  for (int rim = 0; rim < int(2 * g.curve_count()); ++rim) {
    size_t span;
    double t;
    int end;
    rim_of(g, rim, span, t, end);
    double len = 0.0;
    glm::dvec2 prev(0.0);
    bool ok = true;
    for (int j = 0; j <= 32 && ok; ++j) {
      glm::dvec2 cur(0.0);
      ok = view.film_of(v3d(g.local(span, t, kTwoPi * j / 32).p), cur);
      if (j > 0) len += glm::length(cur - prev);
      prev = cur;
    }
    if (!ok) {
      ++skipped;
      continue;
    }
    out.push_back({shape, int(2 * S) + rim, float(std::max(len, 1e-2))});
  }
}

bool CameraSilhouettes<BSplineCurve>::point(const DiffContext& c, const BSplineCurve& g, const SilhouetteCurve& curve, float u01,
                                            const ad::V3<double>& eye, VV& P, ad::V3<double>& dP, double& pdf_param) {
  const size_t S = g.span_count();
  pdf_param = 1.0;
  if (size_t(curve.local) < 2 * S) {
    // The silhouette point at t = u01 on the curve's side, attached at its (t, u): its motion
    // differs from the silhouette's by a slide within the tangent plane, which the camera sees
    // along the outline (no normal component in film space).
    const size_t span = size_t(curve.local) / 2;
    const int side = curve.local % 2 ? 1 : -1;
    const double t = u01;
    double u;
    if (!silhouette_at(g, span, t, vec3d(eye), false, side, 50, u)) return false;
    const TubeLocal L = g.local(span, t, u);
    P = curve_position(c, g, curve.shape, span, t, L.rho);
    dP = v3d(silhouette_tangent(L, vec3d(eye), false));
    return true;
  }
  size_t span;
  double t;
  int end;
  rim_of(g, curve.local - int(2 * S), span, t, end);
  const double u = kTwoPi * u01;
  const TubeLocal L = g.local(span, t, u);
  // A rim point whose adjacent surface faces away from the eye is no visibility boundary: the
  // one-sided tube is invisible from there on both sides of it (as finish_rim requires w . n > 0
  // for the indirect term). Its probes would still catch any other edge passing within the probe
  // offset and count it again (measured: the back half of a nearly edge-on rim doubled the end's
  // derivative, tests/python/test_curves.py, the level view).
  if (!(glm::dot(L.n, vec3d(eye) - L.p) > 0.0)) return false;
  P = curve_position(c, g, curve.shape, span, t, L.rho);
  dP = v3d(L.mu * kTwoPi);
  return true;
}

// ---- locating points ------------------------------------------------------------------------------------
bool curve_locate(const BSplineCurve& g, const Vec3& x, size_t& span_out, double& t_out, double& u_out) {
  const Vec3d xd(x);
  double best = kInfinity;
  for (size_t s = 0; s < g.span_count(); ++s) {
    const Vec3 pad = 1e-3f * (g.span_hi[s] - g.span_lo[s]);
    if (glm::any(glm::lessThan(x, g.span_lo[s] - pad)) || glm::any(glm::greaterThan(x, g.span_hi[s] + pad))) continue;
    // Start at the nearest of 17 points of the centre line, then Newton on h(t) = (x - C) . C' = 0
    // (the foot of x on the centre line). The Hessian of |x - C|^2 / 2, |C'|^2 - (x - C) . C'', is
    // positive near the foot when r is below the curvature radius (but small on the inside of a
    // tight bend: 1 - r kappa); where it is not (below 1e-3 |C'|^2, far from the foot) the step
    // falls back to Gauss-Newton (|C'|^2), which always descends.
    double t = 0.0, d_min = kInfinity;
    for (int j = 0; j <= 16; ++j) {
      const double d = glm::length(xd - g.eval(s, j / 16.0).c);
      if (d < d_min) d_min = d, t = j / 16.0;
    }
    for (int it = 0; it < 40; ++it) {
      const CurveSample cs = g.eval(s, t);
      const Vec3d D = xd - cs.c;
      const double h = glm::dot(D, cs.c1), gn = glm::dot(cs.c1, cs.c1), hess = gn - glm::dot(D, cs.c2);
      const double step = std::clamp(h / (hess > 1e-3 * gn ? hess : gn), -0.25, 0.25);
      const double next = std::clamp(t + step, 0.0, 1.0);
      if (std::abs(next - t) < 1e-15) break;
      t = next;
    }
    const CurveSample cs = g.eval(s, t);
    const Vec3d D = xd - cs.c;
    const double along = std::abs(glm::dot(D, cs.c1)) / glm::length(cs.c1), off = std::abs(glm::length(D) - cs.r);
    const double err = along + off;
    if (err < best) best = err, span_out = s, t_out = t, u_out = g.angle_of(s, t, D);
  }
  // 1e-4 of the radius: the float x_b of a sample is ~1e-7 of the coordinates from the surface.
  return best < kInfinity && best <= 1e-4 * g.eval(span_out, t_out).r + 1e-6 * double(max_component(glm::abs(x)));
}

}  // namespace limn
