// The local pieces every differentiable path replay needs (interior.cpp's material-form replay, the
// heightfield estimator): attaching a vertex to its surface and sliding it along a differentiated
// ray (the shapes' own code, core/diff/shapes/), BSDF and emitter values on the tape.
#pragma once
#include "core/diff/ad/diff_params.h"
#include "core/diff/ad/local_derivatives.h"
#include "core/diff/shapes/all.h"
#include "core/render/bsdfs/fresnel.h"

namespace limn::replay {

using ad::Var;
using VV = ad::V3<Var>;

inline VV constant(const Vec3& v) { return VV(Var(v.x), Var(v.y), Var(v.z)); }

// w with its value replaced by the primal direction and its derivative kept. Directions rebuilt
// from two attached points carry their rounding error divided by the segment length, which on
// short grazing segments visibly changes glossy BSDF values; the primal path used `primal`.
inline VV with_primal_value(const VV& w, const Vec3& primal) {
  return VV(w.x + Var(double(primal.x) - w.x.v), w.y + Var(double(primal.y) - w.y.v), w.z + Var(double(primal.z) - w.z.v));
}

struct Replay {
  const Scene& scene;
  const DiffParams& params;
  PathInputs& in;

  // ---- geometry ---------------------------------------------------------------------------------
  // A vertex attached to its surface at the primal point's material coordinates.
  DiffVertex attach(int shape, int prim, const Vec2& bary, const Vec3& n, const Vec2& uv) const {
    return limn::attach(DiffContext{scene, params, in}, SurfacePoint{shape, prim, bary, n, uv});
  }
  DiffVertex attach(const SurfaceInteraction& si) const { return limn::attach(DiffContext{scene, params, in}, SurfacePoint::of(si)); }
  // The vertex where the differentiated ray (o, d) meets the primal hit's surface.
  DiffVertex ray_hit(const VV& o, const VV& d, const SurfaceInteraction& si, const Ray& primal_ray) const {
    return limn::ray_hit(DiffContext{scene, params, in}, o, d, si, primal_ray);
  }

  // ---- materials and emitters ---------------------------------------------------------------------
  VV reflectance(int bsdf, const Texture& tex, const Var& u, const Var& v) const {
    return texture(tex, params.slot(Parameter::Kind::Reflectance, bsdf), u, v);
  }
  // An area emitter's radiance at texture coordinates (u, v).
  VV emitter_radiance(int emitter, const Texture& tex, const Var& u, const Var& v) const {
    return texture(tex, params.slot(Parameter::Kind::EmitterValue, emitter), u, v);
  }
  // A texture's value at (u, v) with its constant or texels tied to the slots from `slot` on.
  VV texture(const Texture& tex, long slot, const Var& u, const Var& v) const {
    if (!tex.bitmap) {
      const Spectrum& c = tex.value;
      return VV(in.make(c.x, slot), in.make(c.y, slot < 0 ? -1 : slot + 1), in.make(c.z, slot < 0 ? -1 : slot + 2));
    }
    // Bilinear lookup as Bitmap::eval_bilinear, differentiable in the texels and in (u, v).
    const Bitmap& bm = *tex.bitmap;
    const Var x = u * Var(bm.width) - Var(0.5), y = (Var(1.0) - v) * Var(bm.height) - Var(0.5);
    const double fx = std::floor(x.v), fy = std::floor(y.v);
    const Var tx = x - Var(fx), ty = y - Var(fy);
    auto wrap = [](long i, long n) { const long m = i % n; return m < 0 ? m + n : m; };
    VV out;
    const long xs[2] = {wrap(long(fx), bm.width), wrap(long(fx) + 1, bm.width)};
    const long ys[2] = {wrap(long(fy), bm.height), wrap(long(fy) + 1, bm.height)};
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        const Var w = (i ? tx : Var(1.0) - tx) * (j ? ty : Var(1.0) - ty);
        const size_t texel = size_t(ys[j]) * bm.width + size_t(xs[i]);
        const long base = slot < 0 ? -1 : slot + long(3 * texel);
        const Spectrum c = bm.texel(int(xs[i]), int(ys[j]));
        out = out + VV(in.make(c.x, base), in.make(c.y, base < 0 ? -1 : base + 1), in.make(c.z, base < 0 ? -1 : base + 2)) * w;
      }
    return out;
  }
  VV emitter_value(int emitter, const Spectrum& value) const {
    const long slot = params.slot(Parameter::Kind::EmitterValue, emitter);
    return VV(in.make(value.x, slot), in.make(value.y, slot < 0 ? -1 : slot + 1), in.make(value.z, slot < 0 ? -1 : slot + 2));
  }
  // A point light's falloff (a spot's profile; 1 for isotropic lights) along the unit direction
  // from the receiver to the light, on the tape through the receiver's position.
  Var point_falloff(const PointEmitter& pt, const VV& to_light) const {
    return pt.spot ? pt.falloff(-dot(constant(pt.axis), to_light)) : Var(1.0);
  }
  Var alpha(int bsdf, float value) const { return in.make(value, params.slot(Parameter::Kind::Alpha, bsdf)); }

  // f * |cos wo| at x for world directions wi (towards the previous vertex) and wo.
  VV bsdf_eval(int bsdf_index, const DiffVertex& x, const VV& wi_world, const VV& wo_world) const {
    const Bsdf& b = scene.bsdfs[bsdf_index];
    const diff::Frame3<Var> frame(x.ns);
    VV wi = frame.to_local(wi_world), wo = frame.to_local(wo_world);
    bool front = dot(wi_world, x.ng).v > 0.0;  // geometric side, as Bsdf::eval
    if (b.twosided && !front) {
      wi.z = -wi.z;
      wo.z = -wo.z;
      front = true;
    }
    return std::visit([&](const auto& m) -> VV {
      using T = std::decay_t<decltype(m)>;
      if constexpr (std::is_same_v<T, Diffuse>) {
        return diff::eval_diffuse(reflectance(bsdf_index, m.reflectance, x.u, x.v), wi, wo, front);
      } else if constexpr (std::is_same_v<T, RoughConductor>) {
        return diff::eval_rough_conductor(m.distribution.type, alpha(bsdf_index, m.distribution.alpha), m.eta, m.k,
                                          m.specular_reflectance, wi, wo);
      } else if constexpr (std::is_same_v<T, RoughDielectric>) {
        return diff::eval_rough_dielectric(m.distribution.type, alpha(bsdf_index, m.distribution.alpha), double(m.eta),
                                           m.specular_reflectance, m.specular_transmittance, wi, wo);
      } else {
        return VV();  // delta lobes have no density to evaluate
      }
    }, b.model);
  }

  // Throughput of a delta lobe, divided by the primal probability of choosing it (detached), and
  // the outgoing direction as a function of the parameters.
  VV delta_bounce(int bsdf_index, const DiffVertex& x, const VV& wi_world, const BsdfSample& bs, VV& wo_world) const {
    const Bsdf& b = scene.bsdfs[bsdf_index];
    const Var cos_i = dot(wi_world, x.ns);
    if (const auto* c = std::get_if<Conductor>(&b.model)) {
      wo_world = diff::reflect(wi_world, x.ns);
      const Var ci = abs(cos_i);  // twosided conductors reflect on either side
      return VV(fresnel_conductor(ci, c->eta.x, c->k.x) * Var(c->specular_reflectance.x),
                fresnel_conductor(ci, c->eta.y, c->k.y) * Var(c->specular_reflectance.y),
                fresnel_conductor(ci, c->eta.z, c->k.z) * Var(c->specular_reflectance.z));
    }
    const auto& d = std::get<Dielectric>(b.model);
    const Var F = diff::fresnel_dielectric(cos_i, double(d.eta));
    // Divided by the primal lobe probability bs.pdf (F or 1 - F in float), not a double recomputation
    // that can disagree with it next to the critical angle.
    if (bs.wo.z * dot(wi_world, x.ns).v > 0.0) {  // reflection
      wo_world = diff::reflect(wi_world, x.ns);
      return constant(d.specular_reflectance) * (F / Var(bs.pdf));
    }
    const bool outside = cos_i.v >= 0.0;
    const double eta_ti = outside ? 1.0 / d.eta : d.eta;
    const Var cos_t2 = Var(1.0) - Var(eta_ti * eta_ti) * (Var(1.0) - cos_i * cos_i);
    const Var cos_t = sqrt(cos_t2) * Var(outside ? -1.0 : 1.0);
    wo_world = x.ns * (Var(eta_ti) * cos_i + cos_t) - wi_world * Var(eta_ti);
    return constant(d.specular_transmittance) * ((Var(1.0) - F) / Var(bs.pdf) * Var(eta_ti * eta_ti));
  }
};

}  // namespace limn::replay
