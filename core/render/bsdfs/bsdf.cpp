// Evaluation, density and sampling of every BSDF model; the twosided wrapper flips both directions
// into the upper hemisphere before dispatching.
#include "core/render/bsdfs/bsdf.h"

#include "core/math/warp.h"
#include "core/render/bsdfs/fresnel.h"

namespace limn {
namespace {

// ---- diffuse ----------------------------------------------------------------------------------
Spectrum eval_model(const Diffuse& b, const Vec3& wi, const Vec3& wo, const Vec2& uv, bool front) {
  if (!front || wo.z <= 0.0f) return Spectrum(0.0f);
  return b.reflectance.eval(uv) * (kInvPi * wo.z);
}
float pdf_model(const Diffuse&, const Vec3& wi, const Vec3& wo, const Vec2&, bool front) {
  return front ? warp::square_to_cosine_hemisphere_pdf(wo) : 0.0f;
}
std::optional<BsdfSample> sample_model(const Diffuse& b, const Vec3& wi, float, const Vec2& u, const Vec2& uv, bool front) {
  if (!front) return std::nullopt;
  BsdfSample s;
  s.wo = warp::square_to_cosine_hemisphere(u);
  s.pdf = warp::square_to_cosine_hemisphere_pdf(s.wo);
  if (s.pdf <= 0.0f) return std::nullopt;
  s.weight = b.reflectance.eval(uv);
  return s;
}

// ---- smooth conductor -------------------------------------------------------------------------
Spectrum eval_model(const Conductor&, const Vec3&, const Vec3&, const Vec2&) { return Spectrum(0.0f); }
float pdf_model(const Conductor&, const Vec3&, const Vec3&, const Vec2&) { return 0.0f; }
std::optional<BsdfSample> sample_model(const Conductor& b, const Vec3& wi, float, const Vec2&, const Vec2&) {
  if (wi.z <= 0.0f) return std::nullopt;
  BsdfSample s;
  s.wo = reflect_local(wi);
  s.pdf = 1.0f;
  s.delta = true;
  s.weight = b.specular_reflectance * fresnel_conductor(wi.z, b.eta, b.k);
  return s;
}

// ---- rough conductor (Walter et al. 2007, eq. 20) --------------------------------------------
Spectrum eval_model(const RoughConductor& b, const Vec3& wi, const Vec3& wo, const Vec2&) {
  if (wi.z <= 0.0f || wo.z <= 0.0f) return Spectrum(0.0f);
  const Vec3 m = glm::normalize(wi + wo);
  const float D = b.distribution.D(m);
  if (D == 0.0f) return Spectrum(0.0f);
  const float G = b.distribution.G(wi, wo, m);
  return b.specular_reflectance * fresnel_conductor(glm::dot(wi, m), b.eta, b.k) * (D * G / (4.0f * wi.z));
}
float pdf_model(const RoughConductor& b, const Vec3& wi, const Vec3& wo, const Vec2&) {
  if (wi.z <= 0.0f || wo.z <= 0.0f) return 0.0f;
  const Vec3 m = glm::normalize(wi + wo);
  const float dot_wo_m = glm::dot(wo, m);
  // Jacobian of reflection about m: d omega_m / d omega_o = 1 / (4 |wo . m|).
  return dot_wo_m > 0.0f ? b.distribution.pdf(wi, m) / (4.0f * dot_wo_m) : 0.0f;
}
std::optional<BsdfSample> sample_model(const RoughConductor& b, const Vec3& wi, float, const Vec2& u, const Vec2& uv) {
  if (wi.z <= 0.0f) return std::nullopt;
  const Vec3 m = b.distribution.sample(wi, u);
  BsdfSample s;
  s.wo = reflect(wi, m);
  if (s.wo.z <= 0.0f) return std::nullopt;
  s.pdf = pdf_model(b, wi, s.wo, uv);
  if (!(s.pdf > 0.0f)) return std::nullopt;
  s.weight = eval_model(b, wi, s.wo, uv) / s.pdf;
  return s;
}

// ---- smooth dielectric ------------------------------------------------------------------------
Spectrum eval_model(const Dielectric&, const Vec3&, const Vec3&, const Vec2&) { return Spectrum(0.0f); }
float pdf_model(const Dielectric&, const Vec3&, const Vec3&, const Vec2&) { return 0.0f; }
std::optional<BsdfSample> sample_model(const Dielectric& b, const Vec3& wi, float u_lobe, const Vec2&, const Vec2&) {
  if (wi.z == 0.0f) return std::nullopt;
  const DielectricFresnel fr = fresnel_dielectric(wi.z, b.eta);
  BsdfSample s;
  s.delta = true;
  if (u_lobe < fr.F) {
    s.wo = reflect_local(wi);
    s.pdf = fr.F;
    s.weight = b.specular_reflectance;
  } else {
    s.wo = Vec3(-fr.eta_ti * wi.x, -fr.eta_ti * wi.y, fr.cos_t);
    s.pdf = 1.0f - fr.F;
    // Radiance is compressed by (n_i / n_t)^2 when it crosses into the denser side (Veach 1997, 5.2).
    s.weight = b.specular_transmittance * (fr.eta_ti * fr.eta_ti);
    s.eta = fr.eta_it;
  }
  return s;
}

// ---- rough dielectric (Walter et al. 2007, eqs. 16-21, radiance transport) --------------------
struct HalfVector {
  Vec3 m;
  bool reflect;
  float eta_path;  // n_t / n_i for transmission
  bool valid;
};
HalfVector dielectric_half_vector(float eta, const Vec3& wi, const Vec3& wo) {
  HalfVector h{};
  const float ci = wi.z, co = wo.z;
  if (ci == 0.0f || co == 0.0f) return h;
  h.reflect = ci * co > 0.0f;
  h.eta_path = ci > 0.0f ? eta : 1.0f / eta;
  Vec3 m = h.reflect ? wi + wo : wi + wo * h.eta_path;  // generalised half vector (eq. 16)
  const float len = glm::length(m);
  if (!(len > 0.0f)) return h;
  m /= len;
  if (m.z < 0.0f) m = -m;
  // Both directions must lie on the side of m their macro hemisphere says.
  h.valid = glm::dot(wi, m) * ci > 0.0f && glm::dot(wo, m) * co > 0.0f;
  h.m = m;
  return h;
}
Spectrum eval_model(const RoughDielectric& b, const Vec3& wi, const Vec3& wo, const Vec2&) {
  const HalfVector h = dielectric_half_vector(b.eta, wi, wo);
  if (!h.valid) return Spectrum(0.0f);
  const Microfacet& md = b.distribution;
  const float D = md.D(h.m);
  const float G = md.G(wi, wo, h.m);
  const float F = fresnel_dielectric(glm::dot(wi, h.m), b.eta).F;
  if (h.reflect) return b.specular_reflectance * (F * D * G / (4.0f * std::abs(wi.z)));
  const float dot_i = glm::dot(wi, h.m), dot_o = glm::dot(wo, h.m);
  const float denom = dot_i + h.eta_path * dot_o;
  // Walter's eq. 21 times |cos wo|; its n_o^2 cancels against the radiance scale 1 / eta_path^2.
  return b.specular_transmittance * ((1.0f - F) * D * G * std::abs(dot_i * dot_o) / (std::abs(wi.z) * denom * denom));
}
float pdf_model(const RoughDielectric& b, const Vec3& wi, const Vec3& wo, const Vec2&) {
  const HalfVector h = dielectric_half_vector(b.eta, wi, wo);
  if (!h.valid) return 0.0f;
  const Vec3 wi_up = wi.z < 0.0f ? -wi : wi;
  const float pdf_m = b.distribution.pdf(wi_up, h.m);
  const float F = fresnel_dielectric(glm::dot(wi, h.m), b.eta).F;
  const float dot_o = glm::dot(wo, h.m);
  if (h.reflect) return F * pdf_m / (4.0f * std::abs(dot_o));
  const float denom = glm::dot(wi, h.m) + h.eta_path * dot_o;
  // Jacobian of refraction (eq. 17): d omega_m / d omega_o = eta^2 |wo . m| / denom^2.
  return (1.0f - F) * pdf_m * h.eta_path * h.eta_path * std::abs(dot_o) / (denom * denom);
}
std::optional<BsdfSample> sample_model(const RoughDielectric& b, const Vec3& wi, float u_lobe, const Vec2& u,
                                       const Vec2& uv) {
  if (wi.z == 0.0f) return std::nullopt;
  const float sign = wi.z > 0.0f ? 1.0f : -1.0f;
  const Vec3 m = b.distribution.sample(sign * wi, u);
  const float dot_i = glm::dot(wi, m);
  if (dot_i * wi.z <= 0.0f) return std::nullopt;  // back-facing microfacet (full-NDF sampling)
  const DielectricFresnel fr = fresnel_dielectric(dot_i, b.eta);
  BsdfSample s;
  if (u_lobe < fr.F) {
    s.wo = reflect(wi, m);
    if (s.wo.z * wi.z <= 0.0f) return std::nullopt;
  } else {
    s.wo = (fr.eta_ti * dot_i + fr.cos_t) * m - fr.eta_ti * wi;
    if (s.wo.z * wi.z >= 0.0f) return std::nullopt;
    s.eta = fr.eta_it;
  }
  s.pdf = pdf_model(b, wi, s.wo, uv);
  if (!(s.pdf > 0.0f)) return std::nullopt;
  s.weight = eval_model(b, wi, s.wo, uv) / s.pdf;
  return s;
}

// Twosided: mirror both directions (z -> -z) when wi is seen from the back of the surface.
Vec3 flip_z(const Vec3& w) { return Vec3(w.x, w.y, -w.z); }

}  // namespace

// Only the diffuse model decides its side by `front`; the microfacet and dielectric formulas need
// wi in the shading hemisphere they are written for (their values vanish there as wi.z -> 0).
Spectrum Bsdf::eval(const Vec3& wi, const Vec3& wo, const Vec2& uv, bool front) const {
  const bool flip = twosided && !front;
  const Vec3 a = flip ? flip_z(wi) : wi, b = flip ? flip_z(wo) : wo;
  return std::visit([&](const auto& m) {
    if constexpr (std::is_same_v<std::decay_t<decltype(m)>, Diffuse>) return eval_model(m, a, b, uv, front || flip);
    else return eval_model(m, a, b, uv);
  }, model);
}

float Bsdf::pdf(const Vec3& wi, const Vec3& wo, const Vec2& uv, bool front) const {
  const bool flip = twosided && !front;
  const Vec3 a = flip ? flip_z(wi) : wi, b = flip ? flip_z(wo) : wo;
  return std::visit([&](const auto& m) {
    if constexpr (std::is_same_v<std::decay_t<decltype(m)>, Diffuse>) return pdf_model(m, a, b, uv, front || flip);
    else return pdf_model(m, a, b, uv);
  }, model);
}

std::optional<BsdfSample> Bsdf::sample(const Vec3& wi, float u_lobe, const Vec2& u, const Vec2& uv, bool front) const {
  const bool flip = twosided && !front;
  const Vec3 a = flip ? flip_z(wi) : wi;
  auto s = std::visit([&](const auto& m) {
    if constexpr (std::is_same_v<std::decay_t<decltype(m)>, Diffuse>) return sample_model(m, a, u_lobe, u, uv, front || flip);
    else return sample_model(m, a, u_lobe, u, uv);
  }, model);
  if (s && flip) s->wo = flip_z(s->wo);
  if (s && !(std::isfinite(s->pdf) && is_finite(s->weight))) return std::nullopt;
  return s;
}

}  // namespace limn
