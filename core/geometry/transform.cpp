#include "core/geometry/transform.h"

#include <sstream>
#include <stdexcept>

namespace limn {

Transform::Transform(const Mat4d& m) : m_m(m) {
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      if (!std::isfinite(m[c][r])) throw std::invalid_argument("transform matrix has a non-finite entry");
  const double det = glm::determinant(m);
  if (!(std::abs(det) > 1e-30)) {
    std::ostringstream s;
    s << "transform matrix is singular (determinant " << det << ")";
    throw std::invalid_argument(s.str());
  }
  m_inv = glm::inverse(m);
}

Transform Transform::translate(const Vec3d& t) {
  Mat4d m(1.0);
  m[3] = glm::dvec4(t, 1.0);
  return Transform(m, [&] { Mat4d i(1.0); i[3] = glm::dvec4(-t, 1.0); return i; }());
}

Transform Transform::scale(const Vec3d& s) {
  if (s.x == 0.0 || s.y == 0.0 || s.z == 0.0 || !std::isfinite(s.x + s.y + s.z)) {
    std::ostringstream msg;
    msg << "scale must be finite and non-zero (got [" << s.x << ", " << s.y << ", " << s.z << "])";
    throw std::invalid_argument(msg.str());
  }
  Mat4d m(1.0), i(1.0);
  for (int k = 0; k < 3; ++k) {
    m[k][k] = s[k];
    i[k][k] = 1.0 / s[k];
  }
  return Transform(m, i);
}

Transform Transform::rotate(const Vec3d& axis, double angle_degrees) {
  const double len = glm::length(axis);
  if (!(len > 0.0) || !std::isfinite(len)) throw std::invalid_argument("rotation axis must be a non-zero finite vector");
  const Vec3d a = axis / len;
  const double th = angle_degrees * std::numbers::pi / 180.0;
  const double c = std::cos(th), s = std::sin(th), C = 1.0 - c;
  // Rodrigues' rotation matrix, column-major (m[column][row]).
  Mat4d m(1.0);
  m[0] = glm::dvec4(c + a.x * a.x * C, a.y * a.x * C + a.z * s, a.z * a.x * C - a.y * s, 0.0);
  m[1] = glm::dvec4(a.x * a.y * C - a.z * s, c + a.y * a.y * C, a.z * a.y * C + a.x * s, 0.0);
  m[2] = glm::dvec4(a.x * a.z * C + a.y * s, a.y * a.z * C - a.x * s, c + a.z * a.z * C, 0.0);
  return Transform(m, glm::transpose(m));
}

Transform Transform::look_at(const Vec3d& origin, const Vec3d& target, const Vec3d& up) {
  const Vec3d dir0 = target - origin;
  if (!(glm::length(dir0) > 0.0)) throw std::invalid_argument("look_at: origin and target coincide");
  const Vec3d dir = glm::normalize(dir0);
  const Vec3d left0 = glm::cross(up, dir);
  if (!(glm::length(left0) > 1e-12)) throw std::invalid_argument("look_at: up is parallel to the viewing direction");
  const Vec3d left = glm::normalize(left0);
  const Vec3d new_up = glm::cross(dir, left);
  Mat4d m(1.0);
  m[0] = glm::dvec4(left, 0.0);
  m[1] = glm::dvec4(new_up, 0.0);
  m[2] = glm::dvec4(dir, 0.0);
  m[3] = glm::dvec4(origin, 1.0);
  return Transform(m);
}

}  // namespace limn
