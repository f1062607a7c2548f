// Vector types and small helpers shared by the whole core (GLM underneath, float precision).
#pragma once
#include <glm/glm.hpp>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>

namespace limn {

using Vec2 = glm::vec2;
using Vec3 = glm::vec3;
using Vec4 = glm::vec4;
using Mat4 = glm::mat4;
using Vec3d = glm::dvec3;
using Mat4d = glm::dmat4;
using Spectrum = glm::vec3;  // linear RGB

inline constexpr float kPi = std::numbers::pi_v<float>;
inline constexpr float kInvPi = 1.0f / kPi;
inline constexpr float kInvTwoPi = 0.5f / kPi;
inline constexpr float kInvFourPi = 0.25f / kPi;
inline constexpr float kInfinity = std::numeric_limits<float>::infinity();

inline float sqr(float x) { return x * x; }
inline float safe_sqrt(float x) { return std::sqrt(std::max(x, 0.0f)); }
inline float safe_acos(float x) { return std::acos(std::clamp(x, -1.0f, 1.0f)); }
inline float max_component(const Vec3& v) { return std::max(v.x, std::max(v.y, v.z)); }
inline float luminance(const Spectrum& c) { return 0.212671f * c.x + 0.715160f * c.y + 0.072169f * c.z; }
inline bool is_finite(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
inline bool is_black(const Spectrum& c) { return c.x == 0.0f && c.y == 0.0f && c.z == 0.0f; }

// Power heuristic with beta = 2 (Veach 1997, eq. 9.13); pdfs in the same measure.
inline float mis_power(float pdf_a, float pdf_b) {
  const float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
  return a + b > 0.0f ? a / (a + b) : 0.0f;
}

// Bound on the relative rounding error of n chained float operations (Higham; pbrt's gamma).
inline constexpr float gamma_bound(int n) {
  constexpr float eps = std::numeric_limits<float>::epsilon() * 0.5f;
  return (n * eps) / (1.0f - n * eps);
}

}  // namespace limn
