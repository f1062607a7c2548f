// Fresnel equations for dielectric and conductor interfaces (unpolarised light).
#pragma once
#include <algorithm>
#include <cmath>
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

// Exact conductor Fresnel for complex IOR eta + i k (unpolarised), in real arithmetic: the
// complex form (pbrt-v4's FrComplex) costs libgcc's __divsc3 / csqrtf calls, 11 % of a render.
// Templated so that core/diff's tape type (unqualified sqrt, min, max found by ADL) and double
// share it. Equal to the complex form within float rounding (tests/cpp/render/test_bsdf.cpp).
template <typename T>
T fresnel_conductor(const T& cos_i0, double eta, double k) {
  using std::max, std::min, std::sqrt;
  const T cos_i = min(max(cos_i0, T(0.0)), T(1.0));
  const T c2 = cos_i * cos_i, s2 = T(1.0) - c2;
  const double e2 = eta * eta, k2 = k * k;
  const T t0 = T(e2 - k2) - s2;                   // Re((eta + i k)^2) - sin^2
  const T a2b2 = sqrt(t0 * t0 + T(4.0 * e2 * k2));  // |n^2 - sin^2| = a^2 + b^2
  const T t1 = a2b2 + c2;
  const T a = sqrt(max(T(0.5) * (a2b2 + t0), T(0.0)));
  const T t2 = T(2.0) * cos_i * a;
  const T rs = (t1 - t2) / (t1 + t2);
  const T t3 = c2 * a2b2 + s2 * s2;
  const T t4 = t2 * s2;
  const T rp = rs * (t3 - t4) / (t3 + t4);
  return T(0.5) * (rp + rs);
}

inline Spectrum fresnel_conductor(float cos_i, const Spectrum& eta, const Spectrum& k) {
  return Spectrum(fresnel_conductor(cos_i, eta.x, k.x), fresnel_conductor(cos_i, eta.y, k.y),
                  fresnel_conductor(cos_i, eta.z, k.z));
}

}  // namespace limn
