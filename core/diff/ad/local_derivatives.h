// Local building blocks of the interior derivative, templated on the scalar type: T = double gives
// the finite-difference references of the tests, T = ad::Var records derivatives on the tape.
// Geometry: ray/triangle and ray/sphere distances, barycentrics, frames. Materials: Fresnel
// terms, microfacet distributions and BSDF evaluation (f * |cos wo|, as core/render/bsdfs).
#pragma once
#include "core/diff/ad/ad.h"
#include "core/render/bsdfs/fresnel.h"
#include "core/render/bsdfs/microfacet.h"

namespace limn::diff {

using namespace ad;  // V3 and the math functions for both double and Var

// ---- geometry -----------------------------------------------------------------------------------
// Distance along o + t d to the plane of triangle (v0, v1, v2).
template <typename T>
T ray_triangle_t(const V3<T>& o, const V3<T>& d, const V3<T>& v0, const V3<T>& v1, const V3<T>& v2) {
  const V3<T> n = cross(v1 - v0, v2 - v0);
  return dot(n, v0 - o) / dot(n, d);
}

// Barycentrics (b1, b2) of a point p in the plane of the triangle.
template <typename T>
void barycentrics(const V3<T>& p, const V3<T>& v0, const V3<T>& v1, const V3<T>& v2, T& b1, T& b2) {
  const V3<T> e1 = v1 - v0, e2 = v2 - v0, q = p - v0;
  const V3<T> n = cross(e1, e2);
  const T inv = T(1.0) / dot(n, n);
  b1 = dot(cross(q, e2), n) * inv;
  b2 = dot(cross(e1, q), n) * inv;
}

// Distance along o + t d to the sphere (c, r); `far` picks the second root (rays from inside).
template <typename T>
T ray_sphere_t(const V3<T>& o, const V3<T>& d, const V3<T>& c, const T& r, bool far) {
  const V3<T> oc = o - c;
  const T b = dot(oc, d);
  const T disc = b * b - (dot(oc, oc) - r * r);
  const T root = sqrt(max(disc, T(0.0)));
  return far ? -b + root : -b - root;
}

template <typename T>
struct Frame3 {
  V3<T> s, t, n;
  explicit Frame3(const V3<T>& normal) : n(normal) {
    // Duff et al. 2017, as core/math/frame.h; the sign is decided on the value (piecewise smooth).
    const double sign = ad::value(n.z) >= 0.0 ? 1.0 : -1.0;
    const T a = T(-1.0) / (T(sign) + n.z);
    const T b = n.x * n.y * a;
    s = V3<T>(T(1.0) + T(sign) * n.x * n.x * a, T(sign) * b, T(-sign) * n.x);
    t = V3<T>(b, T(sign) + n.y * n.y * a, -n.y);
  }
  V3<T> to_local(const V3<T>& v) const { return V3<T>(dot(v, s), dot(v, t), dot(v, n)); }
  V3<T> to_world(const V3<T>& v) const { return s * v.x + t * v.y + n * v.z; }
};

template <typename T>
V3<T> reflect(const V3<T>& w, const V3<T>& m) { return m * (T(2.0) * dot(w, m)) - w; }

// ---- Fresnel --------------------------------------------------------------------------------------
// (The conductor's is core/render/bsdfs/fresnel.h's templated fresnel_conductor.)
// Dielectric reflectance for cos_i (sign: which side), eta = interior / exterior IOR.
template <typename T>
T fresnel_dielectric(const T& cos_i, double eta) {
  const bool outside = ad::value(cos_i) >= 0.0;
  const double eta_it = outside ? eta : 1.0 / eta, eta_ti = 1.0 / eta_it;
  const T ci = abs(cos_i);
  const T cos_t2 = T(1.0) - T(eta_ti * eta_ti) * (T(1.0) - ci * ci);
  if (ad::value(cos_t2) <= 0.0) return T(1.0);
  const T ct = sqrt(cos_t2);
  const T rs = (ci - T(eta_it) * ct) / (ci + T(eta_it) * ct);
  const T rp = (T(eta_it) * ci - ct) / (T(eta_it) * ci + ct);
  return T(0.5) * (rs * rs + rp * rp);
}

// ---- microfacets ----------------------------------------------------------------------------------
// As Microfacet (core/render/bsdfs/microfacet.h): sin^2 from x and y, never 1 - z^2.
template <typename T>
T microfacet_D(MicrofacetType type, const T& alpha, const V3<T>& m) {
  if (ad::value(m.z) <= 0.0) return T(0.0);
  const T c2 = m.z * m.z, s2 = m.x * m.x + m.y * m.y, a2 = alpha * alpha;
  if (type == MicrofacetType::GGX) {
    const T t = s2 + c2 * a2;
    return a2 / (T(kPi) * t * t);
  }
  const T tan2 = s2 / c2;
  return exp(-tan2 / a2) / (T(kPi) * a2 * c2 * c2);
}

template <typename T>
T microfacet_lambda(MicrofacetType type, const T& alpha, const V3<T>& w) {
  const T c2 = w.z * w.z;
  const T tan2 = (w.x * w.x + w.y * w.y) / c2;
  if (ad::value(tan2) == 0.0) return T(0.0);
  if (type == MicrofacetType::GGX) return T(0.5) * (T(-1.0) + sqrt(T(1.0) + alpha * alpha * tan2));
  const T a = T(1.0) / (alpha * sqrt(tan2));
  if (ad::value(a) >= 1.6) return T(0.0);
  return (T(1.0) - T(1.259) * a + T(0.396) * a * a) / (T(3.535) * a + T(2.181) * a * a);
}

template <typename T>
T microfacet_G1(MicrofacetType type, const T& alpha, const V3<T>& w, const V3<T>& m) {
  if (ad::value(dot(w, m) * w.z) <= 0.0) return T(0.0);
  return T(1.0) / (T(1.0) + microfacet_lambda(type, alpha, w));
}

// ---- BSDF evaluation (local frame; returns f * |cos wo|, RGB) -------------------------------------
// `front`: wi is on the geometric front side (see core/render/bsdfs/bsdf.h).
template <typename T>
V3<T> eval_diffuse(const V3<T>& reflectance, const V3<T>& wi, const V3<T>& wo, bool front) {
  if (!front || ad::value(wo.z) <= 0.0) return V3<T>();
  return reflectance * (wo.z * T(kInvPi));
}

template <typename T>
V3<T> eval_rough_conductor(MicrofacetType type, const T& alpha, const Vec3& eta, const Vec3& k, const Vec3& tint,
                           const V3<T>& wi, const V3<T>& wo) {
  if (ad::value(wi.z) <= 0.0 || ad::value(wo.z) <= 0.0) return V3<T>();
  const V3<T> m = normalize(wi + wo);
  const T D = microfacet_D(type, alpha, m);
  if (ad::value(D) == 0.0) return V3<T>();
  const T G = microfacet_G1(type, alpha, wi, m) * microfacet_G1(type, alpha, wo, m);
  const T common = D * G / (T(4.0) * wi.z);
  const T cos_h = dot(wi, m);
  return V3<T>(fresnel_conductor(cos_h, eta.x, k.x) * common * T(tint.x), fresnel_conductor(cos_h, eta.y, k.y) * common * T(tint.y),
               fresnel_conductor(cos_h, eta.z, k.z) * common * T(tint.z));
}

template <typename T>
V3<T> eval_rough_dielectric(MicrofacetType type, const T& alpha, double eta, const Vec3& tint_r, const Vec3& tint_t,
                            const V3<T>& wi, const V3<T>& wo) {
  const double ci = ad::value(wi.z), co = ad::value(wo.z);
  if (ci == 0.0 || co == 0.0) return V3<T>();
  const bool reflect = ci * co > 0.0;
  const double eta_path = ci > 0.0 ? eta : 1.0 / eta;
  V3<T> m = reflect ? wi + wo : wi + wo * T(eta_path);
  m = normalize(m);
  if (ad::value(m.z) < 0.0) m = -m;
  if (ad::value(dot(wi, m)) * ci <= 0.0 || ad::value(dot(wo, m)) * co <= 0.0) return V3<T>();
  const T D = microfacet_D(type, alpha, m);
  const T G = microfacet_G1(type, alpha, wi, m) * microfacet_G1(type, alpha, wo, m);
  const T F = fresnel_dielectric(dot(wi, m), eta);
  if (reflect) {
    const T v = F * D * G / (T(4.0) * abs(wi.z));
    return V3<T>(v * T(tint_r.x), v * T(tint_r.y), v * T(tint_r.z));
  }
  const T di = dot(wi, m), dout = dot(wo, m);
  const T denom = di + T(eta_path) * dout;
  // Walter et al. 2007 eq. 21 times |cos wo| with the radiance scale folded in (core/render/bsdfs).
  const T v = (T(1.0) - F) * D * G * abs(di * dout) / (abs(wi.z) * denom * denom);
  return V3<T>(v * T(tint_t.x), v * T(tint_t.y), v * T(tint_t.z));
}

}  // namespace limn::diff
