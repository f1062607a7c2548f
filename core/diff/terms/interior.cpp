#include "core/diff/terms/interior.h"

#include "core/diff/terms/replay.h"

namespace limn {
using namespace replay;
using ad::Var;
using VV = ad::V3<Var>;


ad::V3<ad::Var> interior_path_radiance(const Scene& scene, const DiffParams& params, const Ray& camera_ray, Pcg32& rng,
                                       PathInputs& inputs, PathCounters& counters, int max_depth) {
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
      const Spectrum& rad = std::get<AreaEmitter>(scene.emitters[shape.emitter].model).radiance;
      L = L + beta * R.emitter_value(shape.emitter, rad) * Var(w);
    }

    if (max_depth >= 0 && depth + 2 > max_depth) break;

    const Bsdf& bsdf = scene.bsdfs[shape.bsdf];
    const Vec3 wi_local = si.frame.to_local(-ray.d);
    const bool front = glm::dot(ray.d, si.ng) < 0.0f;

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
          contrib = R.bsdf_eval(shape.bsdf, x, wi, w_dir) * R.emitter_value(int(k), area->radiance) * (g / Var(double(pdf_light) * g0));
        } else if (const auto* pt = std::get_if<PointEmitter>(&e.model)) {
          const VV dvec = constant(pt->position) - x.p;
          const Var d2 = dot(dvec, dvec);
          contrib = R.bsdf_eval(shape.bsdf, x, wi, with_primal_value(dvec / sqrt(d2), es.wi)) * R.emitter_value(int(k), pt->intensity) /
                    (d2 * Var(scene.emitter_selection_pdf()));
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
