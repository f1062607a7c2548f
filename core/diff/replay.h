// A light path vertex as a function of the parameters, and the local pieces every differentiable
// path replay needs (interior.cpp's material-form replay, the heightfield estimator): attaching a
// vertex to its surface, sliding it along a differentiated ray, BSDF and emitter values on the tape.
#pragma once
#include "core/diff/diff_params.h"
#include "core/diff/local_derivatives.h"
#include "core/heightfield/diff_heightfield.h"
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

// A path vertex as a function of the parameters.
struct DiffVertex {
  VV p, ng, ns;       // position, geometric normal, shading normal (ns on ng's side)
  Var jacobian{1.0};  // area of the attached surface element relative to its primal area
  Var u{0.0}, v{0.0}; // texture coordinates
};

struct Replay {
  const Scene& scene;
  const DiffParams& params;
  PathInputs& in;

  // ---- geometry ---------------------------------------------------------------------------------
  VV vertex(int shape, uint32_t i) const { return diff_vertex(scene, params, in, shape, i); }
  // Area-weighted vertex normal from the triangles around vertex i, each with its
  // Mesh::normal_sign (exactly as Mesh::update_derived).
  VV vertex_normal(int shape, uint32_t i) const {
    const Mesh& m = scene.shapes[shape].mesh();
    if (params.slot(Parameter::Kind::VertexPositions, shape) < 0) return constant(m.vertex_normals[i]);  // a translation keeps normals
    VV sum;
    for (uint32_t k = m.vertex_face_offsets[i]; k < m.vertex_face_offsets[i + 1]; ++k) {
      const uint32_t f = m.vertex_faces[k];
      const int sign = m.normal_sign(f);
      if (sign == 0) continue;
      const VV a = vertex(shape, m.indices[3 * f]), b = vertex(shape, m.indices[3 * f + 1]), c = vertex(shape, m.indices[3 * f + 2]);
      sum = sum + cross(b - a, c - a) * Var(double(sign));
    }
    return ad::dot(sum, sum).v > 0.0 ? normalize(sum) : constant(m.vertex_normals[i]);
  }
  void triangle(int shape, int prim, VV& v0, VV& v1, VV& v2) const {
    const Mesh& m = scene.shapes[shape].mesh();
    v0 = vertex(shape, m.indices[3 * prim]);
    v1 = vertex(shape, m.indices[3 * prim + 1]);
    v2 = vertex(shape, m.indices[3 * prim + 2]);
  }
  // Normals and uv of a mesh point with (possibly differentiable) barycentrics.
  void mesh_surface(int shape, int prim, const VV& v0, const VV& v1, const VV& v2, const Var& b1, const Var& b2,
                    DiffVertex& x) const {
    const Mesh& m = scene.shapes[shape].mesh();
    const Var b0 = Var(1.0) - b1 - b2;
    const VV n = cross(v1 - v0, v2 - v0);
    x.ng = normalize(n);
    x.ns = x.ng;
    if (!m.face_normals) {
      const uint32_t* idx = &m.indices[3 * size_t(prim)];
      const VV s = vertex_normal(shape, idx[0]) * b0 + vertex_normal(shape, idx[1]) * b1 + vertex_normal(shape, idx[2]) * b2;
      if (ad::dot(s, s).v > 0.0) {
        x.ns = normalize(s);
        if (ad::dot(x.ns, x.ng).v < 0.0) x.ns = -x.ns;
      }
    }
    if (!m.corner_uvs.empty()) {
      const float* t = &m.corner_uvs[6 * size_t(prim)];
      x.u = b0 * Var(t[0]) + b1 * Var(t[2]) + b2 * Var(t[4]);
      x.v = b0 * Var(t[1]) + b1 * Var(t[3]) + b2 * Var(t[5]);
    } else {
      x.u = b1;
      x.v = b2;
    }
  }
  void sphere_params(int shape, VV& c, Var& r) const {
    c = diff_sphere_center(scene, params, in, shape);
    r = diff_sphere_radius(scene, params, in, shape);
  }

  // A vertex attached to its surface at the primal point's material coordinates.
  DiffVertex attach(int shape, int prim, const Vec2& bary, const Vec3& sphere_dir, const Vec2& uv) const {
    DiffVertex x;
    const Shape& sh = scene.shapes[shape];
    if (sh.is_heightfield()) {
      // Material point: fixed grid coordinates (bary = (c, r)), so fixed local (x, y).
      const Heightfield& hf = sh.heightfield();
      const DiffHeightfieldFrame F(scene, params, in, shape);
      const Var lx(hf.local_x(bary.x)), ly(hf.local_y(bary.y));
      Var z, zx, zy;
      F.height(in, lx, ly, z, zx, zy);
      x.p = F.to_world_point(VV(lx, ly, z));
      x.ng = x.ns = normalize(F.to_world_vector(VV(-zx, -zy, Var(1.0))));
      const Var area = sqrt(Var(1.0) + zx * zx + zy * zy);  // dA / (dx dy)
      x.jacobian = area / Var(area.v);
      x.u = Var(uv.x);
      x.v = Var(uv.y);
    } else if (sh.is_mesh()) {
      VV v0, v1, v2;
      triangle(shape, prim, v0, v1, v2);
      const Var b1(bary.x), b2(bary.y);
      x.p = v0 * (Var(1.0) - b1 - b2) + v1 * b1 + v2 * b2;
      mesh_surface(shape, prim, v0, v1, v2, b1, b2, x);
      const Var area2 = length(cross(v1 - v0, v2 - v0));
      x.jacobian = area2 / Var(area2.v);  // 1 at the primal point, exactly
    } else {
      VV c;
      Var r;
      sphere_params(shape, c, r);
      const VV n0 = constant(sphere_dir);
      x.p = c + n0 * r;
      x.ng = x.ns = n0;
      const double r0 = sh.sphere().radius;
      x.jacobian = (r * r) / Var(r0 * r0);
      x.u = Var(uv.x);
      x.v = Var(uv.y);
    }
    return x;
  }
  DiffVertex attach(const SurfaceInteraction& si) const {
    return attach(si.shape, si.prim, si.bary, si.ng, si.uv);
  }

  // The vertex where the differentiated ray (o, d) meets the primal hit's surface.
  DiffVertex ray_hit(const VV& o, const VV& d, const SurfaceInteraction& si, const Ray& primal_ray) const {
    DiffVertex x;
    const Shape& sh = scene.shapes[si.shape];
    if (sh.is_heightfield()) {
      const Heightfield& hf = sh.heightfield();
      const DiffHeightfieldFrame F(scene, params, in, si.shape);
      const Var t = F.ray_t(in, o, d, double(si.t));
      const VV pl = F.to_local_point(o + d * t);
      F.surface(in, pl.x, pl.y, x.p, x.ng);
      x.ns = x.ng;
      // Texture coordinates slide with the hit: u = x / W + 1/2, v = y / D + 1/2.
      x.u = pl.x / Var(hf.width) + Var(0.5);
      x.v = pl.y / Var(hf.depth) + Var(0.5);
    } else if (sh.is_mesh()) {
      VV v0, v1, v2;
      triangle(si.shape, si.prim, v0, v1, v2);
      const Var t = diff::ray_triangle_t(o, d, v0, v1, v2);
      x.p = o + d * t;
      Var b1, b2;
      diff::barycentrics(x.p, v0, v1, v2, b1, b2);
      mesh_surface(si.shape, si.prim, v0, v1, v2, b1, b2, x);
    } else {
      VV c;
      Var r;
      sphere_params(si.shape, c, r);
      // Which root the primal hit was: the near one unless the ray starts inside.
      const Vec3 oc = primal_ray.o - sh.sphere().center;
      const bool far = glm::dot(oc, oc) < sh.sphere().radius * sh.sphere().radius;
      const Var t = diff::ray_sphere_t(o, d, c, r, far);
      x.p = o + d * t;
      x.ng = x.ns = (x.p - c) / r;
      // The hit slides over the sphere: texture coordinates as Sphere::fill_interaction defines them.
      const double two_pi = 2.0 * M_PI;
      const Var phi = atan2(x.ng.y, x.ng.x);
      x.u = (phi.v < 0.0 ? phi + Var(two_pi) : phi) / Var(two_pi);
      x.v = acos(x.ng.z) / Var(M_PI);
    }
    return x;
  }

  // ---- materials and emitters ---------------------------------------------------------------------
  VV reflectance(int bsdf, const Texture& tex, const Var& u, const Var& v) const {
    const long slot = params.slot(Parameter::Kind::Reflectance, bsdf);
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
