// Affine transforms named destination_from_source, e.g. world_from_object.
#pragma once
#include "core/math/vec.h"

namespace limn {

class Transform {
 public:
  Transform() : m_m(1.0), m_inv(1.0) {}
  explicit Transform(const Mat4d& m);  // throws std::invalid_argument if m is singular or not finite

  static Transform translate(const Vec3d& t);
  static Transform scale(const Vec3d& s);
  static Transform rotate(const Vec3d& axis, double angle_degrees);
  // Mitsuba's look_at: local +z looks at target, local +y is up, local +x points to the left.
  static Transform look_at(const Vec3d& origin, const Vec3d& target, const Vec3d& up);

  Transform operator*(const Transform& o) const { return Transform(m_m * o.m_m, o.m_inv * m_inv); }
  Transform inverse() const { return Transform(m_inv, m_m); }

  Vec3 point(const Vec3& p) const { return Vec3(m_m * Vec4d(Vec3d(p), 1.0)); }
  Vec3 vector(const Vec3& v) const { return Vec3(Mat3d(m_m) * Vec3d(v)); }
  // Normals transform by the inverse transpose; the result is normalised.
  Vec3 normal(const Vec3& n) const { return glm::normalize(Vec3(glm::transpose(Mat3d(m_inv)) * Vec3d(n))); }

  const Mat4d& matrix() const { return m_m; }
  const Mat4d& inverse_matrix() const { return m_inv; }
  bool is_identity() const { return m_m == Mat4d(1.0); }

 private:
  using Vec4d = glm::dvec4;
  using Mat3d = glm::dmat3;
  Transform(const Mat4d& m, const Mat4d& inv) : m_m(m), m_inv(inv) {}
  Mat4d m_m, m_inv;
};

}  // namespace limn
