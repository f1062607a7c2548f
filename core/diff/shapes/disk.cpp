#include "core/diff/shapes/disk.h"

#include "core/diff/ad/local_derivatives.h"
#include "core/math/warp.h"

namespace limn {
namespace {

using ad::Var;
using VV = ad::V3<Var>;

VV constant(const Vec3& v) { return VV(Var(v.x), Var(v.y), Var(v.z)); }

// Centre (with the translation parameter) and radius of disk `shape` on the tape.
VV disk_center(const DiffContext& c, int shape, const Disk& d) { return plus_translation(c.params, c.in, shape, constant(d.center)); }
Var disk_radius(const DiffContext& c, int shape, const Disk& d) { return c.in.make(d.radius, c.params.slot(Parameter::Kind::DiskRadius, shape)); }

// The point at unit-disk coordinates (x, y), as a function of the parameters.
VV disk_point(const DiffContext& c, int shape, const Disk& d, double x, double y) {
  return disk_center(c, shape, d) + (constant(d.s) * Var(x) + constant(d.t) * Var(y)) * disk_radius(c, shape, d);
}

float wrap_unit(float x) {
  x -= std::floor(x);
  return std::min(x, std::nextafter(1.0f, 0.0f));
}

// The rim point at angle theta with the boundary direction w (as BoundarySegments<Mesh>'s edges:
// n_b perpendicular to the tangent and w, pointing away from the disk). False where the rim is no
// silhouette along w: w along its tangent, or in the disk's plane (the disk seen edge-on).
bool finish_rim(const Disk& d, float theta, const Vec3& w, BoundaryPoint& out) {
  const float c = std::cos(theta), s = std::sin(theta);
  const Vec3 radial = c * d.s + s * d.t, tangent = -s * d.s + c * d.t;
  const Vec3 txw = glm::cross(tangent, w);
  const float sin_phi = glm::length(txw);
  if (!(sin_phi > 1e-6f)) return false;  // w along the rim (the mesh edges' threshold)
  const float inward = -glm::dot(txw, radial) / sin_phi;  // which side of the plane (tangent, w) the disk lies on
  if (!(std::abs(inward) > 1e-6f)) return false;
  out.n_b = txw / sin_phi * (inward > 0.0f ? -1.0f : 1.0f);
  out.n_out = d.n * (glm::dot(d.n, w) >= 0.0f ? 1.0f : -1.0f);
  out.xb = d.at(Vec2(c, s));
  out.w = w;
  out.jacobian = sin_phi;
  out.delta = probe_offset(d.radius, out.xb);
  out.param = Vec3(c, s, 0.0f);
  return true;
}

float rim_angle(const Disk& d, const Vec3& p) {
  const Vec3 q = p - d.center;
  return std::atan2(glm::dot(q, d.t), glm::dot(q, d.s));
}

// The rim point radially outward from the hit, with the direction towards x_a (the rim of an open
// surface is a silhouette along almost every direction).
class DiskProjector : public ShapeProjector {
 public:
  DiskProjector(const Disk& d, const SegmentSpace& space, int segment) : m_disk(d), m_space(space), m_segment(segment) {}
  std::optional<Projection> project(const Vec3& xa, const SurfaceInteraction& hit, Pcg32& rng) const override {
    const Vec3 q = hit.p - m_disk.center;
    const bool centred = !(glm::length(q - glm::dot(q, m_disk.n) * m_disk.n) > 1e-6f * m_disk.radius);
    const float theta = centred ? 2.0f * kPi * rng.next_float() : rim_angle(m_disk, hit.p);
    const Vec3 xb = m_disk.at(Vec2(std::cos(theta), std::sin(theta)));
    return finish_projection(m_space, m_segment, xa, xb, true, xa - hit.p);
  }

 private:
  const Disk& m_disk;
  const SegmentSpace& m_space;
  int m_segment;
};

}  // namespace

// ---- tape ---------------------------------------------------------------------------------------
VV SurfaceDiff<Disk>::position(const DiffContext& c, const Disk& d, const SurfacePoint& sp) {
  return disk_point(c, sp.shape, d, sp.bary.x, sp.bary.y);
}

DiffVertex SurfaceDiff<Disk>::attach(const DiffContext& c, const Disk& d, const SurfacePoint& sp) {
  DiffVertex x;
  x.p = position(c, d, sp);
  x.ng = x.ns = constant(d.n);
  const Var r = disk_radius(c, sp.shape, d);
  x.jacobian = (r * r) / Var(double(d.radius) * double(d.radius));
  x.u = Var(sp.uv.x);
  x.v = Var(sp.uv.y);
  return x;
}

DiffVertex SurfaceDiff<Disk>::ray_hit(const DiffContext& c, const Disk& d, const VV& o, const VV& dir, const SurfaceInteraction& si,
                                      const Ray&) {
  DiffVertex x;
  const VV center = disk_center(c, si.shape, d);
  const Var r = disk_radius(c, si.shape, d);
  const VV n = constant(d.n);
  // The plane through the centre along the differentiated ray.
  const Var t = dot(center - o, n) / dot(dir, n);
  x.p = o + dir * t;
  x.ng = x.ns = n;
  // The hit slides over the disk: its uv as Disk::fill_interaction defines them.
  const VV q = x.p - center;
  const Var lx = dot(q, constant(d.s)) / r, ly = dot(q, constant(d.t)) / r;
  x.u = sqrt(lx * lx + ly * ly);
  const Var phi = atan2(ly, lx);
  x.v = (phi.v < 0.0 ? phi + Var(2.0 * M_PI) : phi) / Var(2.0 * M_PI);
  return x;
}

// ---- boundary segments ----------------------------------------------------------------------------
void BoundarySegments<Disk>::append(const Scene&, const Disk& d, int shape, bool moving, BoundaryPart part,
                                    std::vector<BoundarySegment>& out) {
  if (part != BoundaryPart::Perimeter) return;  // flat: no interior part
  const float measure = 2.0f * kPi * d.radius * 4.0f * kPi;  // length x the sphere of directions
  out.push_back({shape, 0, measure, measure, moving, part});
}

bool BoundarySegments<Disk>::sample(const Scene&, const Disk& d, const BoundarySegment&, float f, float u1, float u2, float pdf_select,
                                    BoundaryPoint& out) {
  out.pdf = pdf_select / (2.0f * kPi * d.radius) * warp::square_to_uniform_sphere_pdf();
  return finish_rim(d, 2.0f * kPi * f, warp::square_to_uniform_sphere(Vec2(u1, u2)), out);
}

Vec3 BoundarySegments<Disk>::invert(const Scene&, const Disk& d, const BoundarySegment&, const Vec3& xb, const Vec3& w) {
  const Vec2 q = warp::uniform_sphere_to_square(w);
  return Vec3(wrap_unit(rim_angle(d, xb) * kInvTwoPi), q.x, q.y);
}

bool BoundarySegments<Disk>::sample_delta(const Scene&, const Disk& d, const BoundarySegment&, float f, float pdf_select,
                                          const Emitter& light, BoundaryPoint& out) {
  const float theta = 2.0f * kPi * f;
  const Vec3 xb = d.at(Vec2(std::cos(theta), std::sin(theta)));
  Vec3 w;
  if (const auto* point = std::get_if<PointEmitter>(&light.model)) {
    const Vec3 v = xb - point->position;
    if (!(glm::length(v) > 0.0f)) return false;
    w = glm::normalize(v);
  } else {
    w = std::get<DirectionalEmitter>(light.model).direction;
  }
  out.pdf = pdf_select / (2.0f * kPi * d.radius);
  return finish_rim(d, theta, w, out) && out.pdf > 0.0f && std::isfinite(out.pdf);
}

VV BoundarySegments<Disk>::attached_point(const DiffContext& c, const Disk& d, const BoundarySegment& s, const BoundaryPoint& p) {
  return disk_point(c, s.shape, d, p.param.x, p.param.y);  // p.param: (cos, sin) of the rim angle
}

std::unique_ptr<ShapeProjector> BoundarySegments<Disk>::projector(const Scene&, const Disk& d, const SegmentSpace& space, int,
                                                                  const std::vector<int>& segments, MeshProjection) {
  return std::make_unique<DiskProjector>(d, space, segments.front());
}

// ---- camera silhouettes ---------------------------------------------------------------------------
void CameraSilhouettes<Disk>::append(const Scene&, const Disk& d, int shape, const CameraView& view, std::vector<SilhouetteCurve>& out,
                                     uint64_t& skipped) {
  // Selection weight: the projected perimeter, from a 64-gon.
  double len = 0.0;
  glm::dvec2 prev(0.0);
  for (int i = 0; i <= 64; ++i) {
    const double phi = 2.0 * M_PI * i / 64;
    const Vec3 p = d.at(Vec2(float(std::cos(phi)), float(std::sin(phi))));
    glm::dvec2 cur;
    if (!view.film_of(ad::V3<double>(p.x, p.y, p.z), cur)) {
      ++skipped;  // the rim crosses the near plane
      return;
    }
    if (i > 0) len += glm::length(cur - prev);
    prev = cur;
  }
  if (len > 0.0) out.push_back({shape, 0, float(len)});
}

bool CameraSilhouettes<Disk>::point(const DiffContext& c, const Disk& d, const SilhouetteCurve& curve, float u, const ad::V3<double>&,
                                    VV& P, ad::V3<double>& dP, double& pdf_param) {
  const double phi = 2.0 * M_PI * u;
  P = disk_point(c, curve.shape, d, std::cos(phi), std::sin(phi));
  const Vec3 tangent = d.radius * (-float(std::sin(phi)) * d.s + float(std::cos(phi)) * d.t);
  dP = ad::V3<double>(tangent.x, tangent.y, tangent.z);
  pdf_param = 1.0 / (2.0 * M_PI);
  return true;
}

void CameraSilhouettes<Disk>::sides(const Scene&, const Disk& d, const SilhouetteCurve& curve, const Vec3& P, const ad::V3<double>& eye,
                                    CurveSides& out) {
  const float theta = rim_angle(d, P);
  out.count = 1;
  SurfaceInteraction& si = out.surface[0];
  d.fill_interaction(Vec2(std::cos(theta), std::sin(theta)), si);
  si.shape = curve.shape;
  out.inward[0] = d.center - P;
  out.facing[0] = glm::dot(Vec3d(d.n), Vec3d(eye.x, eye.y, eye.z) - Vec3d(P)) > 0.0;
}

}  // namespace limn
