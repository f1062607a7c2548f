// Isotropic microfacet distributions (GGX / Trowbridge-Reitz and Beckmann) with the separable Smith
// shadowing term. Directions are in the local shading frame (z = macro normal).
#pragma once
#include "core/math/frame.h"

namespace limn {

enum class MicrofacetType { GGX, Beckmann };

struct Microfacet {
  MicrofacetType type = MicrofacetType::Beckmann;
  float alpha = 0.1f;          // > 0; roughness as in Walter et al. 2007
  bool sample_visible = true;  // GGX: sample visible normals (Heitz 2018); Beckmann: always the full NDF

  // sin^2 of a unit vector's angle to z, from its x and y: 1 - z^2 cancels in float once the angle
  // is below ~3e-4 rad, which a lobe of alpha 1e-4 lives in.
  static float sin2(const Vec3& v) { return v.x * v.x + v.y * v.y; }

  // Normal distribution D(m), per unit projected area.
  float D(const Vec3& m) const {
    if (m.z <= 0.0f) return 0.0f;
    const float c2 = m.z * m.z, s2 = sin2(m), a2 = alpha * alpha;
    if (type == MicrofacetType::GGX) {
      const float t = s2 + c2 * a2;  // c^2 (a^2 - 1) + 1, without the cancellation
      return a2 / (kPi * t * t);
    }
    const float tan2 = s2 / c2;
    return std::exp(-tan2 / a2) / (kPi * a2 * c2 * c2);
  }
  // Smith Lambda(w).
  float lambda(const Vec3& w) const {
    const float c2 = w.z * w.z;
    const float tan2 = sin2(w) / c2;
    if (tan2 == 0.0f) return 0.0f;
    if (type == MicrofacetType::GGX) return 0.5f * (-1.0f + std::sqrt(1.0f + alpha * alpha * tan2));
    const float a = 1.0f / (alpha * std::sqrt(tan2));
    // Rational approximation of the Beckmann Lambda (Walter et al. 2007, eq. 27).
    return a >= 1.6f ? 0.0f : (1.0f - 1.259f * a + 0.396f * a * a) / (3.535f * a + 2.181f * a * a);
  }
  // Masking of w by microfacets of normal m; zero when w sees the back of m or of the macro surface.
  float G1(const Vec3& w, const Vec3& m) const {
    if (glm::dot(w, m) * w.z <= 0.0f) return 0.0f;
    return 1.0f / (1.0f + lambda(w));
  }
  float G(const Vec3& wi, const Vec3& wo, const Vec3& m) const { return G1(wi, m) * G1(wo, m); }

  // Density of sampled normals m (solid angle of m) given wi in the upper hemisphere.
  float pdf(const Vec3& wi, const Vec3& m) const {
    if (type == MicrofacetType::GGX && sample_visible) {
      if (wi.z <= 0.0f) return 0.0f;
      return G1(wi, m) * std::max(0.0f, glm::dot(wi, m)) * D(m) / wi.z;
    }
    return D(m) * std::max(m.z, 0.0f);
  }
  // Samples a microfacet normal in the upper hemisphere; wi must have wi.z > 0.
  Vec3 sample(const Vec3& wi, const Vec2& u) const {
    if (type == MicrofacetType::GGX && sample_visible) {
      // Heitz 2018, "Sampling the GGX distribution of visible normals".
      const Vec3 vh = glm::normalize(Vec3(alpha * wi.x, alpha * wi.y, wi.z));
      const float lensq = vh.x * vh.x + vh.y * vh.y;
      const Vec3 t1 = lensq > 0.0f ? Vec3(-vh.y, vh.x, 0.0f) / std::sqrt(lensq) : Vec3(1, 0, 0);
      const Vec3 t2 = glm::cross(vh, t1);
      const float r = std::sqrt(u.x), phi = 2.0f * kPi * u.y;
      const float p1 = r * std::cos(phi);
      const float s = 0.5f * (1.0f + vh.z);
      const float p2 = (1.0f - s) * safe_sqrt(1.0f - p1 * p1) + s * r * std::sin(phi);
      const Vec3 nh = p1 * t1 + p2 * t2 + safe_sqrt(1.0f - p1 * p1 - p2 * p2) * vh;
      return glm::normalize(Vec3(alpha * nh.x, alpha * nh.y, std::max(1e-7f, nh.z)));  // keep m.z > 0
    }
    float tan2;
    if (type == MicrofacetType::GGX) tan2 = alpha * alpha * u.x / std::max(1.0f - u.x, 1e-7f);
    else tan2 = -alpha * alpha * std::log(std::max(1.0f - u.x, 1e-30f));  // guard log(0) at u = 1
    const float cos_t = 1.0f / std::sqrt(1.0f + tan2);
    const float sin_t = std::sqrt(tan2) * cos_t;  // not sqrt(1 - cos^2): that cancels for small alpha
    const float phi = 2.0f * kPi * u.y;
    return Vec3(sin_t * std::cos(phi), sin_t * std::sin(phi), cos_t);
  }
};

}  // namespace limn
