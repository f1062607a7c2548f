#include "core/geometry/shapes/sphere.h"

#include <stdexcept>
#include "core/geometry/embree_user.h"
#include "core/math/warp.h"

namespace limn {

bool Sphere::intersect(const Ray& ray, float& t_hit) const {
  // Solve |o + t d - c|^2 = r^2 with the numerically stable form of the quadratic roots.
  const Vec3d oc = Vec3d(ray.o) - Vec3d(center);
  const Vec3d d(ray.d);
  const double a = glm::dot(d, d);
  const double b = 2.0 * glm::dot(oc, d);
  // c = |oc|^2 - r^2 via the distance from the centre to the ray's line (Hearn & Baker; pbrt-v4,
  // "Ray Tracing Gems" ch. 7), which keeps precision when the ray starts far from a small sphere.
  const Vec3d perp = oc - (glm::dot(oc, d) / a) * d;
  const double r = double(radius);
  const double disc = 4.0 * a * (r * r - glm::dot(perp, perp));
  if (disc < 0.0) return false;
  const double root = std::sqrt(disc);
  const double q = b < 0.0 ? -0.5 * (b - root) : -0.5 * (b + root);
  double t0 = q / a, t1 = q != 0.0 ? (glm::dot(oc, oc) - r * r) / q : t0;
  if (t0 > t1) std::swap(t0, t1);
  double t = t0;
  if (!(t > ray.tmin) || !(t < ray.tmax)) {
    t = t1;
    if (!(t > ray.tmin) || !(t < ray.tmax)) return false;
  }
  t_hit = float(t);
  return true;
}

void Sphere::fill_interaction(const Vec3& p_hit, SurfaceInteraction& si) const {
  // Reproject onto the surface; the remaining error is a few ulps of |p| (pbrt-v4: gamma(5)).
  Vec3 dir = p_hit - center;
  const float len = glm::length(dir);
  dir = len > 0.0f ? dir / len : Vec3(0, 0, 1);
  si.p = center + radius * dir;
  si.p_error = gamma_bound(5) * (glm::abs(si.p) + glm::abs(center) + Vec3(radius));
  si.ng = si.ns = dir;
  // Spherical texture coordinates (Mitsuba's convention: u along azimuth, v from +z to -z).
  const float phi = std::atan2(dir.y, dir.x);
  si.uv = Vec2((phi < 0.0f ? phi + 2.0f * kPi : phi) * kInvTwoPi, safe_acos(dir.z) * kInvPi);
  si.bary = si.uv;
  si.prim = 0;
  si.frame = Frame(si.ns);
}

PositionSample Sphere::sample_position(const Vec2& u, float) const {
  const Vec3 n = warp::square_to_uniform_sphere(u);
  SurfaceInteraction si;
  fill_interaction(center + radius * n, si);
  return PositionSample{si.p, si.ng, si.uv, 1.0f / area(), 0, si.uv};
}

namespace {
void sphere_bounds(const RTCBoundsFunctionArguments* args) {
  const Sphere& s = *static_cast<const Sphere*>(args->geometryUserPtr);
  // Widened by a few ulps: the box is rounded to float, the intersector works in double.
  const float r = s.radius * (1.0f + 1e-6f) + 1e-6f * max_component(glm::abs(s.center));
  embree_user::set_bounds(args->bounds_o, s.center - Vec3(r), s.center + Vec3(r));
}
}  // namespace

RTCGeometry Sphere::create_embree_geometry(RTCDevice device) const { return embree_user::new_geometry(device, *this, sphere_bounds); }

void Sphere::list_parameters(const std::string& id, int index, std::vector<Parameter>& out) {
  out.push_back({id + ".center", Parameter::Kind::SphereCenter, index, &center.x, {3}, true});
  out.push_back({id + ".radius", Parameter::Kind::SphereRadius, index, &radius, {}, true});
}

void Sphere::validate_parameter(const Parameter& p, const std::string& where) const {
  if (p.kind == Parameter::Kind::SphereCenter) {
    if (!std::isfinite(p.data[0]) || !std::isfinite(p.data[1]) || !std::isfinite(p.data[2]))
      throw std::invalid_argument(where + ": center is not finite (" + format_values(p.data, 3) + ")");
  } else if (!(std::isfinite(p.data[0]) && p.data[0] > 0.0f)) {
    throw std::invalid_argument(where + ": must be finite and > 0 (got " + std::to_string(p.data[0]) + ")");
  }
  // p.data is this sphere's centre or radius, edited in place.
  if (max_component(glm::abs(center)) + radius > kMaxCoordinate)
    throw std::invalid_argument(where + ": the sphere (centre " + format_values(&center.x, 3) + ", radius " + format_values(&radius, 1) +
                                ") reaches beyond the traceable range (|coordinate| <= 1e18)");
}

void Sphere::geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const {
  values.insert(values.end(), {center.x, center.y, center.z, radius});
  lo = glm::min(lo, center - Vec3(radius));
  hi = glm::max(hi, center + Vec3(radius));
}

}  // namespace limn
