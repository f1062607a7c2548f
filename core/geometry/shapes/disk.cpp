#include "core/geometry/shapes/disk.h"

#include <stdexcept>
#include "core/geometry/embree_user.h"
#include "core/math/warp.h"

namespace limn {

bool Disk::intersect(const Ray& ray, float& t_hit) const {
  // The plane through the centre, then the distance from the centre, in double.
  const Vec3d nd(n), d(ray.d);
  const double dn = glm::dot(d, nd);
  if (dn == 0.0) return false;  // parallel: a disk has no thickness to meet
  const double t = glm::dot(Vec3d(center) - Vec3d(ray.o), nd) / dn;
  if (!(t > ray.tmin) || !(t < ray.tmax)) return false;
  const Vec3d q = Vec3d(ray.o) + t * d - Vec3d(center);
  if (glm::dot(q, q) > double(radius) * double(radius)) return false;
  t_hit = float(t);
  return true;
}

void Disk::fill_interaction(const Vec2& local, SurfaceInteraction& si) const {
  si.p = at(local);
  // Error of c + r (x s + y t) in float: a few ulps of each term (pbrt-v4's gamma bounds).
  si.p_error = gamma_bound(6) * (glm::abs(center) + radius * (glm::abs(local.x * s) + glm::abs(local.y * t)));
  si.ng = si.ns = n;
  // Mitsuba's disk: uv = (distance from the centre, angle / 2 pi), both in [0, 1].
  const float phi = std::atan2(local.y, local.x);
  si.uv = Vec2(std::min(glm::length(local), 1.0f), (phi < 0.0f ? phi + 2.0f * kPi : phi) * kInvTwoPi);
  si.bary = local;
  si.prim = 0;
  si.frame = Frame(si.ns);
}

void Disk::fill_hit(const Ray& ray, float t_hit, unsigned, const Vec2&, SurfaceInteraction& si) const {
  // Unit-disk coordinates of the hit (projected onto the plane: the hit lies on it up to rounding).
  const Vec3d q = Vec3d(ray(t_hit)) - Vec3d(center);
  Vec2 local(float(glm::dot(q, Vec3d(s)) / radius), float(glm::dot(q, Vec3d(t)) / radius));
  const float len = glm::length(local);
  if (len > 1.0f) local /= len;
  fill_interaction(local, si);
}

PositionSample Disk::sample_position(const Vec2& u, float) const {
  const Vec2 local = warp::square_to_disk_concentric(u);
  SurfaceInteraction si;
  fill_interaction(local, si);
  return PositionSample{si.p, si.ng, si.uv, 1.0f / area(), 0, local};
}

void Disk::bounds(Vec3& lo, Vec3& hi) const {
  // Per axis the disk reaches r sqrt(1 - n_i^2) from its centre.
  const Vec3 reach = radius * glm::sqrt(glm::max(Vec3(1.0f) - n * n, Vec3(0.0f)));
  lo = center - reach;
  hi = center + reach;
}

namespace {
void disk_bounds(const RTCBoundsFunctionArguments* args) {
  const Disk& d = *static_cast<const Disk*>(args->geometryUserPtr);
  Vec3 lo, hi;
  d.bounds(lo, hi);
  // Widened by a few ulps: the box is rounded to float, the intersector works in double.
  const Vec3 pad(d.radius * 1e-6f + 1e-6f * max_component(glm::abs(d.center)));
  embree_user::set_bounds(args->bounds_o, lo - pad, hi + pad);
}
}  // namespace

RTCGeometry Disk::create_embree_geometry(RTCDevice device) const { return embree_user::new_geometry(device, *this, disk_bounds); }

void Disk::list_parameters(const std::string& id, int index, std::vector<Parameter>& out) {
  out.push_back({id + ".radius", Parameter::Kind::DiskRadius, index, &radius, {}, true});
}

void Disk::validate_parameter(const Parameter& p, const std::string& where) const {
  if (!(std::isfinite(p.data[0]) && p.data[0] > 0.0f))
    throw std::invalid_argument(where + ": must be finite and > 0 (got " + std::to_string(p.data[0]) + ")");
  if (max_component(glm::abs(center)) + radius > kMaxCoordinate)
    throw std::invalid_argument(where + ": the disk (centre " + format_values(&center.x, 3) + ", radius " + format_values(&radius, 1) +
                                ") reaches beyond the traceable range (|coordinate| <= 1e18)");
}

void Disk::geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const {
  values.insert(values.end(), {center.x, center.y, center.z, radius});
  Vec3 a, b;
  bounds(a, b);
  lo = glm::min(lo, a);
  hi = glm::max(hi, b);
}

}  // namespace limn
