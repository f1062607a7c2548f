// The closed set of BSDFs. Directions are in the local shading frame (z = shading normal); wi
// points towards the previous path vertex (the viewer), wo towards the next one (the light).
// eval() returns f(wi, wo) * |cos(wo)| (Mitsuba's convention); pdfs are per solid angle of wo.
// `front` says whether wi is on the front side of the *geometric* surface. It, not the sign of
// wi.z, decides which side a one-sided or twosided diffuse surface is seen from: with interpolated
// normals wi.z can turn negative near silhouettes, and a cut-off there would be a discontinuity
// inside the triangles that no boundary term samples.
#pragma once
#include <optional>
#include <string>
#include <variant>
#include "core/render/bsdfs/microfacet.h"
#include "core/render/textures/texture.h"

namespace limn {

struct BsdfSample {
  Vec3 wo;
  float pdf = 0.0f;       // solid angle; for delta lobes, the discrete probability of the lobe
  Spectrum weight{0.0f};  // eval / pdf (f |cos| / pdf; delta lobes: their throughput)
  float eta = 1.0f;       // relative IOR crossed (n_t / n_i), 1 for reflection
  bool delta = false;
};

struct Diffuse {
  Texture reflectance;
};

// Smooth (delta) conductor.
struct Conductor {
  Spectrum eta{0.0f}, k{1.0f};         // complex IOR; (0, 1) reflects everything (material "none")
  Spectrum specular_reflectance{1.0f};
};

struct RoughConductor {
  Spectrum eta{0.0f}, k{1.0f};
  Spectrum specular_reflectance{1.0f};
  Microfacet distribution;
};

// Smooth (delta) dielectric interface.
struct Dielectric {
  float eta = 1.5046f / 1.000277f;     // int_ior / ext_ior
  Spectrum specular_reflectance{1.0f}, specular_transmittance{1.0f};
};

struct RoughDielectric {
  float eta = 1.5046f / 1.000277f;
  Spectrum specular_reflectance{1.0f}, specular_transmittance{1.0f};
  Microfacet distribution;
};

using BsdfModel = std::variant<Diffuse, Conductor, RoughConductor, Dielectric, RoughDielectric>;

struct Bsdf {
  std::string id;
  BsdfModel model;
  bool twosided = false;  // reflect from both sides (for non-transmissive models only)

  Spectrum eval(const Vec3& wi, const Vec3& wo, const Vec2& uv, bool front) const;
  float pdf(const Vec3& wi, const Vec3& wo, const Vec2& uv, bool front) const;
  // u_lobe picks a lobe, u a direction within it.
  std::optional<BsdfSample> sample(const Vec3& wi, float u_lobe, const Vec2& u, const Vec2& uv, bool front) const;
  // True when every lobe is a Dirac delta (no point in emitter sampling).
  bool is_delta() const {
    return std::holds_alternative<Conductor>(model) || std::holds_alternative<Dielectric>(model);
  }
  bool transmits() const {
    return std::holds_alternative<Dielectric>(model) || std::holds_alternative<RoughDielectric>(model);
  }
};

}  // namespace limn
