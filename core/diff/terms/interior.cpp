#include "core/diff/terms/interior.h"

#include "core/diff/terms/replay.h"

namespace limn {
using namespace replay;
using ad::Var;
using VV = ad::V3<Var>;

namespace {

// Smooth shading's geometric horizon (docs/derivatives.md, "Smooth shading"). The leak test keeps
// an outgoing direction w at x only on the geometric side of the incoming one, s = side (w . n_g) > 0,
// a cut through the shading hemisphere where f |cos_s| L jumps from a non-zero value to 0. It moves
// with the geometry, so the derivative gains the boundary integral over the great circle s = 0:
//     d/dtheta int f L H(s) dw = int_{s=0} f L (ds/dtheta) dl(w),
//     ds/dtheta = side (w . dn_g/dtheta + (dy/dtheta - dx/dtheta) . n_g / |y - x|),
// with x and the point y it sees along w attached to their surfaces (the relative velocity of the
// cut, as in the indirect term). One uniform w on the circle (pdf 1 / 2 pi); f L are the limits
// from the kept side. Flat shading has f |cos_s| = 0 on the circle, and no term.
VV horizon_term(const Scene& scene, const DiffParams& params, PathInputs& in, const DiffVertex& x, const SurfaceInteraction& si,
                const Bsdf& bsdf, const Vec3& wi_local, bool front, const VV& beta, int budget, Pcg32 rng_copy, PathCounters& counters) {
  // A stream of its own: the replay must consume random numbers exactly as the primal path does.
  const uint64_t s = (uint64_t(rng_copy.next_u32()) << 32) | rng_copy.next_u32();
  Pcg32 rng(mix_bits(s), 0x686f72697a6f6eULL);
  const float side = front ? 1.0f : -1.0f;
  const Frame frame(si.ng);
  const float phi = 2.0f * kPi * rng.next_float();
  const Vec3 w = std::cos(phi) * frame.s + std::sin(phi) * frame.t;
  const Spectrum f = bsdf.eval(wi_local, si.frame.to_local(w), si.uv, front);
  if (is_black(f) || !is_finite(f)) return VV();  // below the shading hemisphere too: no jump
  // The radiance just above the cut, along a direction 1e-4 rad to the kept side (the ray must
  // leave the surface's own plane; the limit is approached at first order in that angle).
  const Vec3 w_kept = glm::normalize(w + side * 1e-4f * si.ng);
  const Ray ray = spawn_ray(si, w_kept);
  Pcg32 rng_path = rng;
  const Spectrum L = path_radiance(scene, ray, rng_path, counters, PathLimits{budget, false});
  if (is_black(L) || !is_finite(L)) return VV();
  // The cut's velocity: the normal's turn, and the ends' motion relative to x's plane.
  const DiffContext c{scene, params, in};
  Var v = dot(constant(w), x.ng);
  SurfaceInteraction y;
  counters.rays++;
  if (scene.intersect(ray, y)) {
    const VV y_p = params.moves(y.shape) ? attached_position(c, SurfacePoint::of(y)) : constant(y.p);
    v = v + dot(y_p - x.p, constant(si.ng)) / Var(double(glm::length(y.p - si.p)));
  }
  v = (v - Var(v.v)) * Var(double(side));  // its value is 0 on the circle; only the derivative counts
  if (v.is_constant()) return VV();
  const ad::V3<double> b = ad::values(beta);
  const Spectrum weight = Spectrum(float(b.x), float(b.y), float(b.z)) * f * L * (2.0f * kPi);
  return constant(weight) * v;
}

}  // namespace


ad::V3<ad::Var> interior_path_radiance(const Scene& scene, const DiffParams& params, const Ray& camera_ray, Pcg32& rng,
                                       PathInputs& inputs, PathCounters& counters, int max_depth, bool horizon) {
  const IntegratorSettings& cfg = scene.integrator;
  VV L;
  if (max_depth == 0) return L;
  const Replay R{scene, params, inputs};

  // Primal state, exactly as path_radiance() keeps it.
  Spectrum beta_primal(1.0f);
  Ray ray = camera_ray;
  float prev_pdf = 0.0f;
  bool prev_delta = true;
  Vec3 prev_p_primal(0.0f);
  float eta_scale = 1.0f;

  // Differentiable state.
  VV beta(Var(1.0), Var(1.0), Var(1.0));     // throughput up to the current vertex
  VV ray_o = constant(camera_ray.o), ray_d = constant(camera_ray.d);  // the ray, when it is followed
  bool follow_ray = true;                    // next vertex slides along (ray_o, ray_d)
  DiffVertex prev;                           // last non-delta vertex (the BSDF sample came from there)
  VV prev_wi;
  int prev_bsdf = -1;
  Vec3 prev_wo_primal(0.0f);

  for (int depth = 0;; ++depth) {
    SurfaceInteraction si;
    counters.rays++;
    const bool hit = scene.intersect(ray, si);

    if (!hit) {
      if (depth == 0 && cfg.hide_emitters) break;
      if (!follow_ray) {  // the sampled direction escapes: f / pdf with the direction held fixed
        const VV w = constant(prev_wo_primal);
        beta = beta * R.bsdf_eval(prev_bsdf, prev, prev_wi, w) / Var(prev_pdf);
      }
      for (int idx : scene.infinite_emitters) {
        const Emitter& e = scene.emitters[idx];
        const float w = prev_delta || !cfg.emitter_sampling ? 1.0f : mis_power(prev_pdf, pdf_infinite(e, ray.d) * scene.emitter_selection_pdf());
        VV Le = constant(eval_infinite(e, ray.d));
        if (const auto* c = std::get_if<ConstantEmitter>(&e.model)) Le = R.emitter_value(idx, c->radiance);
        L = L + beta * Le * Var(w);
      }
      break;
    }

    // The vertex as a function of the parameters, and the throughput reaching it.
    DiffVertex x;
    VV wi;  // towards the previous vertex
    if (follow_ray) {
      x = R.ray_hit(ray_o, ray_d, si, ray);
      wi = -ray_d;
    } else {
      x = R.attach(si);
      const VV dvec = x.p - prev.p;
      const Var d2 = dot(dvec, dvec);
      const VV w = with_primal_value(dvec / sqrt(d2), prev_wo_primal);
      const Var cos_x = abs(dot(x.ng, w));
      // Material form: solid-angle sample at prev -> area at x; g / g0 is 1 at the primal point.
      const Var g = cos_x / d2 * x.jacobian;
      const double g0 = cos_x.v / d2.v;
      beta = beta * R.bsdf_eval(prev_bsdf, prev, prev_wi, w) * (g / Var(double(prev_pdf) * g0));
      wi = -w;
    }

    const Shape& shape = scene.shapes[si.shape];
    if (shape.emitter >= 0 && glm::dot(si.ng, ray.d) < 0.0f && !(depth == 0 && cfg.hide_emitters)) {
      float w = 1.0f;
      if (!prev_delta && cfg.emitter_sampling) {
        const float pdf_light = pdf_emitter_area(scene.emitters[shape.emitter], shape, prev_p_primal, si.p, si.ng) *
                                scene.emitter_selection_pdf();
        w = mis_power(prev_pdf, pdf_light);
      }
      const Texture& rad = std::get<AreaEmitter>(scene.emitters[shape.emitter].model).radiance;
      L = L + beta * R.emitter_radiance(shape.emitter, rad, x.u, x.v) * Var(w);
    }

    if (max_depth >= 0 && depth + 2 > max_depth) break;

    const Bsdf& bsdf = scene.bsdfs[shape.bsdf];
    const Vec3 wi_local = si.frame.to_local(-ray.d);
    const bool front = glm::dot(ray.d, si.ng) < 0.0f;

    // Smooth shading (n_s != n_g) of reflective BSDFs: the geometric horizon's boundary term.
    if (horizon && !bsdf.is_delta() && !bsdf.transmits() && glm::dot(si.ns, si.ng) < 1.0f - 1e-6f)
      L = L + horizon_term(scene, params, inputs, x, si, bsdf, wi_local, front, beta, max_depth < 0 ? -1 : max_depth - depth - 1, rng,
                           counters);

    // Next-event estimation: the primal sample and its tests (shared with path_radiance()).
    if (cfg.emitter_sampling && !bsdf.is_delta() && !scene.emitters.empty()) {
      const DirectLightSample d = sample_direct_light(scene, si, bsdf, wi_local, front, rng, counters);
      if (d.ok) {
        const size_t k = d.emitter;
        const Emitter& e = scene.emitters[k];
        const EmitterSample& es = d.es;
        const float pdf_light = d.pdf_light, w = d.mis;
        VV contrib;
        if (const auto* area = std::get_if<AreaEmitter>(&e.model)) {
          const PositionSample& ps = es.position;
          const DiffVertex y = R.attach(area->shape, ps.prim, ps.bary, ps.n, ps.uv);
          const VV dvec = y.p - x.p;
          const Var d2 = dot(dvec, dvec);
          const VV w_dir = with_primal_value(dvec / sqrt(d2), es.wi);
          const Var cos_y = -dot(y.ng, w_dir);
          const Var g = cos_y / d2 * y.jacobian;
          const double g0 = cos_y.v / d2.v;
          contrib = R.bsdf_eval(shape.bsdf, x, wi, w_dir) * R.emitter_radiance(int(k), area->radiance, y.u, y.v) * (g / Var(double(pdf_light) * g0));
        } else if (const auto* pt = std::get_if<PointEmitter>(&e.model)) {
          const VV dvec = constant(pt->position) - x.p;
          const Var d2 = dot(dvec, dvec);
          const VV w_dir = with_primal_value(dvec / sqrt(d2), es.wi);
          contrib = R.bsdf_eval(shape.bsdf, x, wi, w_dir) * R.emitter_value(int(k), pt->intensity) / (d2 * Var(scene.emitter_selection_pdf()));
          if (pt->spot) contrib = contrib * R.point_falloff(*pt, w_dir);
        } else if (const auto* dir = std::get_if<DirectionalEmitter>(&e.model)) {
          contrib = R.bsdf_eval(shape.bsdf, x, wi, constant(-dir->direction)) * R.emitter_value(int(k), dir->irradiance) /
                    Var(scene.emitter_selection_pdf());
        } else {
          VV Le = constant(es.radiance);
          if (const auto* c = std::get_if<ConstantEmitter>(&e.model)) Le = R.emitter_value(int(k), c->radiance);
          contrib = R.bsdf_eval(shape.bsdf, x, wi, constant(es.wi)) * Le / Var(pdf_light);
        }
        L = L + beta * contrib * Var(w);
      }
    }
    if (!cfg.bsdf_sampling) break;

    // BSDF sampling (same random numbers and tests as path_radiance()).
    const float u_lobe = rng.next_float();
    const auto bs = bsdf.sample(wi_local, u_lobe, rng.next_2d(), si.uv, front);
    if (!bs) break;
    const Vec3 wo = si.frame.to_world(bs->wo);
    if (glm::dot(wo, si.ng) * bs->wo.z <= 0.0f) break;
    if (bs->delta) {
      VV wo_var;
      beta = beta * R.delta_bounce(shape.bsdf, x, wi, *bs, wo_var);
      ray_o = x.p;
      ray_d = wo_var;
      follow_ray = true;
    } else {
      prev = x;
      prev_wi = wi;
      prev_bsdf = shape.bsdf;
      prev_wo_primal = wo;
      follow_ray = false;
    }
    beta_primal *= bs->weight;
    prev_pdf = bs->pdf;
    prev_delta = bs->delta;
    prev_p_primal = si.p;
    eta_scale *= bs->eta * bs->eta;
    ray = spawn_ray(si, wo);

    if (depth + 1 >= cfg.rr_depth) {
      const float q = russian_roulette(beta_primal, eta_scale, rng);
      if (q == 0.0f) break;
      beta = beta / Var(q);
      beta_primal /= q;
    }
    if (is_black(beta_primal)) break;
  }
  return L;
}

}  // namespace limn
