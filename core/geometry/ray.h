// Rays and the surface records produced by intersecting them.
#pragma once
#include "core/math/frame.h"

namespace limn {

// The largest coordinate limn accepts for geometry and cameras: Embree traces rays whose origin
// and direction components are within FLT_LARGE (1.844e18); a ray leaving a surface starts there.
inline constexpr float kMaxCoordinate = 1e18f;

struct Ray {
  Vec3 o, d;            // origin, unit direction
  float tmin = 0.0f;    // parametric interval [tmin, tmax]
  float tmax = kInfinity;
  Vec3 operator()(float t) const { return o + t * d; }
};

// Where a ray met a surface. Positions and normals are in world space.
struct SurfaceInteraction {
  float t = kInfinity;
  Vec3 p;               // hit position
  Vec3 p_error;         // conservative absolute error bound of p (per axis), for ray spawning
  Vec3 ng;              // geometric normal (unit, facing the shape's outside / triangle winding)
  Vec3 ns;              // shading normal (unit, same hemisphere as ng)
  Vec2 uv;              // texture coordinates
  Vec2 bary;            // barycentrics (b1, b2) for triangles, (u, v) surface coordinates for spheres
  int shape = -1;       // index into Scene::shapes
  int prim = -1;        // triangle index, 0 for spheres
  Frame frame;          // shading frame around ns

  bool valid() const { return shape >= 0; }
};

// Origin offset past the rounding error of p along the geometric normal, on the side of w
// (pbrt-v4's OffsetRayOrigin idea): a ray leaving there cannot re-hit the same surface point.
inline Vec3 offset_ray_origin(const Vec3& p, const Vec3& p_error, const Vec3& ng, const Vec3& w) {
  // p_error bounds our reconstruction of p; Embree's intersection of the new ray also rounds, by a
  // few ulps of the coordinates' magnitude (2^-20 |p| is about 8 ulps). Without that term a hit that
  // is exact (e.g. on the plane z = 0) would get no offset and re-hit its own triangle at t = 0.
  const float d = glm::dot(glm::abs(ng), p_error) + 0x1p-20f * max_component(glm::abs(p));
  Vec3 offset = d * ng;
  if (glm::dot(w, ng) < 0.0f) offset = -offset;
  Vec3 po = p + offset;
  // Round away from p so the offset survives the addition.
  for (int i = 0; i < 3; ++i) {
    if (offset[i] > 0.0f) po[i] = std::nextafter(po[i], kInfinity);
    else if (offset[i] < 0.0f) po[i] = std::nextafter(po[i], -kInfinity);
  }
  return po;
}

inline Ray spawn_ray(const SurfaceInteraction& si, const Vec3& d) {
  return Ray{offset_ray_origin(si.p, si.p_error, si.ng, d), d, 0.0f, kInfinity};
}

// Ray from a surface point to a target point; stops just short of the target so it does not count
// the target's own surface as an occluder (1 - 1e-4 of the distance between offset end points).
inline Ray spawn_ray_to(const SurfaceInteraction& si, const Vec3& target) {
  const Vec3 o = offset_ray_origin(si.p, si.p_error, si.ng, target - si.p);
  Vec3 d = target - o;
  const float dist = glm::length(d);
  d /= dist;
  return Ray{o, d, 0.0f, dist * (1.0f - 1e-4f)};
}

}  // namespace limn
