#include "core/diff/shapes/sphere.h"

#include "core/diff/ad/local_derivatives.h"
#include "core/math/frame.h"
#include "core/math/warp.h"

namespace limn {
namespace {

using ad::Var;
using VV = ad::V3<Var>;

VV constant(const Vec3& v) { return VV(Var(v.x), Var(v.y), Var(v.z)); }

const Sphere& sphere_of(const Scene& scene, int shape) { return std::get<Sphere>(scene.shapes[shape].geometry); }

// The circle where rays from a viewpoint e graze the sphere (its silhouette seen from e): the unit
// normals n = cos_a a + sin_a s, for unit s perpendicular to a, where a points from the centre
// towards e and cos_a = r / |e - c|; its points are c + r n. One routine for the camera's outline
// (the primary term, on the tape), a point light's shadow outline (sample_delta) and the
// projection (Listing 1). False when e is not outside the sphere by more than `margin` r.
template <typename T>
struct GrazingCircle {
  ad::V3<T> a;
  T cos_a, sin_a;
  ad::V3<T> normal(const ad::V3<T>& s) const { return a * cos_a + s * sin_a; }
};
template <typename T>
bool grazing_circle(const ad::V3<T>& c, const T& r, const ad::V3<T>& e, double margin, GrazingCircle<T>& out) {
  const ad::V3<T> to_e = e - c;
  const T d = length(to_e);
  if (!(ad::value(d) > ad::value(r) * (1.0 + margin))) return false;
  out.a = to_e / d;
  out.cos_a = r / d;
  out.sin_a = sqrt(T(1.0) - out.cos_a * out.cos_a);
  return true;
}
// A directional light's outline: the great circle perpendicular to its direction.
GrazingCircle<float> grazing_circle_at_infinity(const Vec3& towards) {
  return {ad::V3<float>(towards.x, towards.y, towards.z), 0.0f, 1.0f};
}
ad::V3<float> v3(const Vec3& v) { return ad::V3<float>(v.x, v.y, v.z); }
Vec3 vec3(const ad::V3<float>& v) { return Vec3(v.x, v.y, v.z); }

// The camera's outline as a centre, a radius and its plane's frame (e1, e2).
template <typename T>
bool outline(const ad::V3<T>& c, const T& r, const ad::V3<double>& eye, ad::V3<T>& q, T& rho, ad::V3<T>& e1, ad::V3<T>& e2) {
  GrazingCircle<T> g;
  if (!grazing_circle(c, r, ad::V3<T>(T(eye.x), T(eye.y), T(eye.z)), 0.0, g)) return false;  // the eye is inside: no silhouette
  q = c + g.a * (r * g.cos_a);
  rho = r * g.sin_a;
  const diff::Frame3<T> f(-g.a);
  e1 = f.s;
  e2 = f.t;
  return true;
}

float wrap_unit(float x) {
  x -= std::floor(x);
  return std::min(x, std::nextafter(1.0f, 0.0f));
}

void finish_sphere(const Sphere& sp, const Vec3& n, const Vec3& w, BoundaryPoint& out) {
  out.xb = sp.center + sp.radius * n;
  out.w = w;
  out.n_b = n;  // growing along n covers the background with the sphere
  out.n_out = n;
  out.jacobian = 1.0f / sp.radius;  // normal curvature, the same in every direction
  out.delta = probe_offset(sp.radius, out.xb);
  out.param = n;
}

// Listing 1 of the projective-sampling paper: the silhouette point seen from x_a in the plane of
// x_a, the centre and the hit.
class SphereProjector : public ShapeProjector {
 public:
  SphereProjector(const Sphere& s, const SegmentSpace& space, int segment) : m_sphere(s), m_space(space), m_segment(segment) {}

  std::optional<Projection> project(const Vec3& xa, const SurfaceInteraction& hit, Pcg32&) const override {
    const Sphere& sp = m_sphere;
    const int segment = m_segment;
    const Vec3 n = glm::normalize(hit.p - sp.center);
    GrazingCircle<float> circle;
    if (!grazing_circle(v3(sp.center), sp.radius, v3(xa), 1e-4, circle)) {
      // xa (almost) inside: no silhouette; keep x_b, take the tangential direction closest to xa - x_b.
      const Vec3 w0 = glm::normalize(xa - hit.p);
      const Vec3 t = w0 - glm::dot(w0, n) * n;
      if (!(glm::length(t) > 1e-6f)) return std::nullopt;
      const Vec3 xb = sp.center + sp.radius * n;
      return Projection{m_space.invert(segment, xb, glm::normalize(t)), segment, xb, glm::normalize(t), false};
    }
    // The circle's point in the plane of x_a, the centre and the hit.
    const Vec3 a = vec3(circle.a);
    Vec3 side = n - glm::dot(n, a) * a;
    if (!(glm::length(side) > 1e-6f)) {  // the hit faces xa head-on: any side will do
      const Frame f(a);
      side = f.s;
    }
    side = glm::normalize(side);
    const Vec3 xb = sp.center + sp.radius * vec3(circle.normal(v3(side)));
    // Section 5: the original direction made tangential keeps what the segment saw at x_a.
    const Vec3 w_orig = glm::normalize(xa - hit.p);
    const Vec3 nx = glm::normalize(xb - sp.center);
    return finish_projection(m_space, segment, xa, xb, true, w_orig - glm::dot(w_orig, nx) * nx);
  }

 private:
  const Sphere& m_sphere;
  const SegmentSpace& m_space;
  int m_segment;
};

}  // namespace

// ---- tape ---------------------------------------------------------------------------------------
ad::V3<ad::Var> sphere_center(const DiffContext& c, int shape) {
  const Sphere& s = sphere_of(c.scene, shape);
  PathInputs& in = c.in;
  const long cs = c.params.slot(Parameter::Kind::SphereCenter, shape);
  return plus_translation(c.params, in, shape, ad::V3<ad::Var>(in.make(s.center.x, cs), in.make(s.center.y, cs < 0 ? -1 : cs + 1),
                                                               in.make(s.center.z, cs < 0 ? -1 : cs + 2)));
}

ad::Var sphere_radius(const DiffContext& c, int shape) {
  return c.in.make(sphere_of(c.scene, shape).radius, c.params.slot(Parameter::Kind::SphereRadius, shape));
}

VV SurfaceDiff<Sphere>::position(const DiffContext& c, const Sphere&, const SurfacePoint& sp) {
  const ad::V3<ad::Var> n(ad::Var(sp.n.x), ad::Var(sp.n.y), ad::Var(sp.n.z));
  return sphere_center(c, sp.shape) + n * sphere_radius(c, sp.shape);
}

DiffVertex SurfaceDiff<Sphere>::attach(const DiffContext& c, const Sphere& s, const SurfacePoint& sp) {
  DiffVertex x;
  x.p = position(c, s, sp);
  const Var r = sphere_radius(c, sp.shape);
  const VV n0 = constant(sp.n);
  x.ng = x.ns = n0;
  const double r0 = s.radius;
  x.jacobian = (r * r) / Var(r0 * r0);
  x.u = Var(sp.uv.x);
  x.v = Var(sp.uv.y);
  return x;
}

DiffVertex SurfaceDiff<Sphere>::ray_hit(const DiffContext& c, const Sphere& s, const VV& o, const VV& d, const SurfaceInteraction& si,
                                        const Ray& primal_ray) {
  DiffVertex x;
  const VV center = sphere_center(c, si.shape);
  const Var r = sphere_radius(c, si.shape);
  // Which root the primal hit was: the near one unless the ray starts inside.
  const Vec3 oc = primal_ray.o - s.center;
  const bool far = glm::dot(oc, oc) < s.radius * s.radius;
  const Var t = diff::ray_sphere_t(o, d, center, r, far);
  x.p = o + d * t;
  x.ng = x.ns = (x.p - center) / r;
  // The hit slides over the sphere: texture coordinates as Sphere::fill_interaction defines them.
  const double two_pi = 2.0 * M_PI;
  const Var phi = atan2(x.ng.y, x.ng.x);
  x.u = (phi.v < 0.0 ? phi + Var(two_pi) : phi) / Var(two_pi);
  x.v = acos(x.ng.z) / Var(M_PI);
  return x;
}

// ---- boundary segments ----------------------------------------------------------------------------
void BoundarySegments<Sphere>::append(const Scene&, const Sphere& s, int shape, bool moving, BoundaryPart part,
                                      std::vector<BoundarySegment>& out) {
  // Weight: the measure (area x 2 pi) times the curvature 1 / r.
  if (part == BoundaryPart::Interior) out.push_back({shape, 0, s.area() * 2.0f * kPi, 8.0f * kPi * kPi * s.radius, moving, part});
}

bool BoundarySegments<Sphere>::sample(const Scene&, const Sphere& sp, const BoundarySegment&, float f, float u1, float u2,
                                      float pdf_select, BoundaryPoint& out) {
  const Vec3 n = warp::square_to_uniform_sphere(Vec2(f, u1));
  const Frame frame(n);
  const float phi = 2.0f * kPi * u2;
  finish_sphere(sp, n, std::cos(phi) * frame.s + std::sin(phi) * frame.t, out);
  out.pdf = pdf_select / sp.area() * kInvTwoPi;
  return true;
}

Vec3 BoundarySegments<Sphere>::invert(const Scene&, const Sphere& sp, const BoundarySegment&, const Vec3& xb, const Vec3& w) {
  const Vec3 n = glm::normalize(xb - sp.center);
  const Vec2 q = warp::uniform_sphere_to_square(n);
  const Frame frame(n);
  const float phi = std::atan2(glm::dot(w, frame.t), glm::dot(w, frame.s));
  return Vec3(q.x, q.y, wrap_unit(phi * kInvTwoPi));
}

bool BoundarySegments<Sphere>::sample_delta(const Scene&, const Sphere& sp, const BoundarySegment&, float f, float pdf_select,
                                            const Emitter& light, BoundaryPoint& out) {
  const auto* point = std::get_if<PointEmitter>(&light.model);
  const auto* directional = std::get_if<DirectionalEmitter>(&light.model);
  // The sphere's silhouette circle seen from the light.
  GrazingCircle<float> circle;
  if (!point) circle = grazing_circle_at_infinity(-directional->direction);
  else if (!grazing_circle(v3(sp.center), sp.radius, v3(point->position), 1e-4, circle)) return false;  // the light is (almost) inside
  const float sin_alpha = circle.sin_a;
  const Frame frame(vec3(circle.a));
  const float psi = 2.0f * kPi * f;
  const Vec3 n = glm::normalize(vec3(circle.normal(v3(std::cos(psi) * frame.s + std::sin(psi) * frame.t))));
  const Vec3 xb = sp.center + sp.radius * n;
  const Vec3 w = point ? glm::normalize(xb - point->position) : directional->direction;
  finish_sphere(sp, n, w, out);
  out.jacobian = 1.0f;  // the circle's tangent is perpendicular to w: sin(phi) = 1
  out.pdf = pdf_select / (2.0f * kPi * sp.radius * sin_alpha);
  return out.pdf > 0.0f && std::isfinite(out.pdf);
}

VV BoundarySegments<Sphere>::attached_point(const DiffContext& c, const Sphere& sp, const BoundarySegment& s, const BoundaryPoint& p) {
  return SurfaceDiff<Sphere>::position(c, sp, SurfacePoint{s.shape, 0, Vec2(0.0f), p.param, Vec2(0.0f)});  // p.param: the unit normal
}

std::unique_ptr<ShapeProjector> BoundarySegments<Sphere>::projector(const Scene&, const Sphere& s, const SegmentSpace& space, int,
                                                                    const std::vector<int>& segments, MeshProjection) {
  return std::make_unique<SphereProjector>(s, space, segments.front());
}

// ---- camera silhouettes ---------------------------------------------------------------------------
void CameraSilhouettes<Sphere>::append(const Scene&, const Sphere& s, int shape, const CameraView& view, std::vector<SilhouetteCurve>& out,
                                       uint64_t& skipped) {
  ad::V3<double> q, e1, e2;
  double rho;
  if (!outline(ad::V3<double>(s.center.x, s.center.y, s.center.z), double(s.radius), view.eye, q, rho, e1, e2)) return;
  // Selection weight: the projected perimeter, from a 64-gon.
  double len = 0;
  glm::dvec2 prev(0.0);
  bool ok = true;
  for (int i = 0; i <= 64 && ok; ++i) {
    const double phi = 2 * M_PI * i / 64;
    glm::dvec2 cur(0.0);
    ok = view.film_of(q + (e1 * std::cos(phi) + e2 * std::sin(phi)) * rho, cur);
    if (i > 0) len += glm::length(cur - prev);
    prev = cur;
  }
  if (!ok) {
    ++skipped;
    return;
  }
  out.push_back({shape, 0, float(len)});
}

bool CameraSilhouettes<Sphere>::point(const DiffContext& c, const Sphere&, const SilhouetteCurve& curve, float u, const ad::V3<double>& eye,
                                      VV& P, ad::V3<double>& dP, double& pdf_param) {
  const VV center = sphere_center(c, curve.shape);
  const Var r = sphere_radius(c, curve.shape);
  VV q, e1, e2;
  Var rho;
  if (!outline(center, r, eye, q, rho, e1, e2)) return false;
  const double phi = 2 * M_PI * u;
  P = q + (e1 * Var(std::cos(phi)) + e2 * Var(std::sin(phi))) * rho;
  dP = (ad::values(e1) * -std::sin(phi) + ad::values(e2) * std::cos(phi)) * rho.v;
  pdf_param = 1.0 / (2 * M_PI);
  return true;
}

}  // namespace limn
