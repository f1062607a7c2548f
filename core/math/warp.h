// Warps from the unit square to common domains, each with its density in the target measure.
#pragma once
#include "core/math/vec.h"

namespace limn::warp {

// Shirley-Chiu concentric map to the unit disk; pdf (area) = 1/pi.
inline Vec2 square_to_disk_concentric(const Vec2& u) {
  const Vec2 o = 2.0f * u - Vec2(1.0f);
  if (o.x == 0.0f && o.y == 0.0f) return Vec2(0.0f);
  float r, phi;
  if (std::abs(o.x) > std::abs(o.y)) {
    r = o.x;
    phi = (kPi / 4.0f) * (o.y / o.x);
  } else {
    r = o.y;
    phi = (kPi / 2.0f) - (kPi / 4.0f) * (o.x / o.y);
  }
  return r * Vec2(std::cos(phi), std::sin(phi));
}
inline float square_to_disk_concentric_pdf(const Vec2& p) { return glm::dot(p, p) <= 1.0f ? kInvPi : 0.0f; }

// Uniform on the unit sphere; pdf (solid angle) = 1/(4 pi).
inline Vec3 square_to_uniform_sphere(const Vec2& u) {
  const float z = 1.0f - 2.0f * u.y;
  const float r = safe_sqrt(1.0f - z * z);
  const float phi = 2.0f * kPi * u.x;
  return Vec3(r * std::cos(phi), r * std::sin(phi), z);
}
inline float square_to_uniform_sphere_pdf() { return kInvFourPi; }
// Exact inverse of square_to_uniform_sphere for a unit vector.
inline Vec2 uniform_sphere_to_square(const Vec3& w) {
  float phi = std::atan2(w.y, w.x) * kInvTwoPi;
  if (phi < 0.0f) phi += 1.0f;
  return Vec2(std::min(phi, std::nextafter(1.0f, 0.0f)), std::clamp(0.5f * (1.0f - w.z), 0.0f, std::nextafter(1.0f, 0.0f)));
}

// Uniform on the upper (z >= 0) hemisphere; pdf (solid angle) = 1/(2 pi).
inline Vec3 square_to_uniform_hemisphere(const Vec2& u) {
  const float z = u.y;
  const float r = safe_sqrt(1.0f - z * z);
  const float phi = 2.0f * kPi * u.x;
  return Vec3(r * std::cos(phi), r * std::sin(phi), z);
}
inline float square_to_uniform_hemisphere_pdf(const Vec3& w) { return w.z >= 0.0f ? kInvTwoPi : 0.0f; }

// Cosine-weighted upper hemisphere (Malley's method); pdf (solid angle) = cos(theta)/pi.
inline Vec3 square_to_cosine_hemisphere(const Vec2& u) {
  const Vec2 d = square_to_disk_concentric(u);
  return Vec3(d.x, d.y, safe_sqrt(1.0f - glm::dot(d, d)));
}
inline float square_to_cosine_hemisphere_pdf(const Vec3& w) { return w.z > 0.0f ? w.z * kInvPi : 0.0f; }

// Uniform in the cone around +z with cos(half angle) = cos_max; pdf (solid angle) = 1/(2 pi (1 - cos_max)).
inline Vec3 square_to_uniform_cone(const Vec2& u, float cos_max) {
  const float z = 1.0f - u.y * (1.0f - cos_max);
  const float r = safe_sqrt(1.0f - z * z);
  const float phi = 2.0f * kPi * u.x;
  return Vec3(r * std::cos(phi), r * std::sin(phi), z);
}
inline float square_to_uniform_cone_pdf(const Vec3& w, float cos_max) {
  return w.z >= cos_max ? 1.0f / (2.0f * kPi * (1.0f - cos_max)) : 0.0f;
}

// Uniform barycentrics (b1, b2) of a triangle; pdf (area of the unit triangle) = 2.
inline Vec2 square_to_uniform_triangle(const Vec2& u) {
  const float t = safe_sqrt(1.0f - u.x);
  return Vec2(1.0f - t, u.y * t);
}

}  // namespace limn::warp
