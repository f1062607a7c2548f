// Orthonormal frame around a unit normal; local z is the normal.
#pragma once
#include "core/math/vec.h"

namespace limn {

struct Frame {
  Vec3 s, t, n;

  Frame() : s(1, 0, 0), t(0, 1, 0), n(0, 0, 1) {}
  // Branchless basis of Duff et al. 2017, "Building an orthonormal basis, revisited".
  explicit Frame(const Vec3& normal) : n(normal) {
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z);
    const float b = n.x * n.y * a;
    s = Vec3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    t = Vec3(b, sign + n.y * n.y * a, -n.y);
  }
  Vec3 to_local(const Vec3& v) const { return Vec3(glm::dot(v, s), glm::dot(v, t), glm::dot(v, n)); }
  Vec3 to_world(const Vec3& v) const { return s * v.x + t * v.y + n * v.z; }
};

// Direction helpers in a local frame (z up).
inline float cos_theta(const Vec3& w) { return w.z; }
inline float abs_cos_theta(const Vec3& w) { return std::abs(w.z); }
inline Vec3 reflect_local(const Vec3& w) { return Vec3(-w.x, -w.y, w.z); }
inline Vec3 reflect(const Vec3& w, const Vec3& m) { return 2.0f * glm::dot(w, m) * m - w; }

}  // namespace limn
