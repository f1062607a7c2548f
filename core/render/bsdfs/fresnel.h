// Fresnel equations for dielectric and conductor interfaces (unpolarised light).
#pragma once
#include <complex>
#include "core/math/vec.h"

namespace limn {

struct DielectricFresnel {
  float F;          // reflectance
  float cos_t;      // cosine of the transmitted direction, sign opposite to cos_i (0 under TIR)
  float eta_it;     // n_transmitted / n_incident along this crossing
  float eta_ti;     // 1 / eta_it
};

// cos_i: cosine between the incident direction (pointing away from the surface) and the normal;
// eta: interior / exterior index of refraction.
inline DielectricFresnel fresnel_dielectric(float cos_i, float eta) {
  const bool outside = cos_i >= 0.0f;
  const float eta_it = outside ? eta : 1.0f / eta, eta_ti = 1.0f / eta_it;
  const float ci = std::abs(cos_i);
  const float cos_t2 = 1.0f - eta_ti * eta_ti * (1.0f - ci * ci);
  if (cos_t2 <= 0.0f) return {1.0f, 0.0f, eta_it, eta_ti};  // total internal reflection
  const float ct = std::sqrt(cos_t2);
  const float rs = (ci - eta_it * ct) / (ci + eta_it * ct);
  const float rp = (eta_it * ci - ct) / (eta_it * ci + ct);
  return {0.5f * (rs * rs + rp * rp), outside ? -ct : ct, eta_it, eta_ti};
}

// Exact conductor Fresnel for complex IOR eta + i k, per RGB channel (pbrt-v4's FrComplex form).
inline float fresnel_conductor(float cos_i, float eta, float k) {
  using C = std::complex<float>;
  cos_i = std::clamp(cos_i, 0.0f, 1.0f);
  const C n(eta, k);
  const float sin2_i = 1.0f - cos_i * cos_i;
  const C sin2_t = sin2_i / (n * n);
  const C cos_t = std::sqrt(C(1.0f) - sin2_t);
  const C r_parl = (n * cos_i - cos_t) / (n * cos_i + cos_t);
  const C r_perp = (cos_i - n * cos_t) / (cos_i + n * cos_t);
  return 0.5f * (std::norm(r_parl) + std::norm(r_perp));
}

inline Spectrum fresnel_conductor(float cos_i, const Spectrum& eta, const Spectrum& k) {
  return Spectrum(fresnel_conductor(cos_i, eta.x, k.x), fresnel_conductor(cos_i, eta.y, k.y),
                  fresnel_conductor(cos_i, eta.z, k.z));
}

}  // namespace limn
