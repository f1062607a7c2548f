#include "core/render/integrators/path.h"

namespace limn {
namespace {

bool emits_towards(const Scene& scene, const SurfaceInteraction& si, const Vec3& d) {
  const Shape& s = scene.shapes[si.shape];
  return s.emitter >= 0 && glm::dot(si.ng, d) < 0.0f;  // area emitters emit from their front side
}

Spectrum area_radiance(const Scene& scene, const SurfaceInteraction& si) {
  return std::get<AreaEmitter>(scene.emitters[scene.shapes[si.shape].emitter].model).radiance.eval(si.uv);
}

}  // namespace

DirectLightSample sample_direct_light(const Scene& scene, const SurfaceInteraction& si, const Bsdf& bsdf, const Vec3& wi_local,
                                      bool front, Pcg32& rng, PathCounters& counters) {
  DirectLightSample d;
  const size_t n = scene.emitters.size();
  d.emitter = std::min(size_t(rng.next_float() * n), n - 1);
  const Vec2 u = rng.next_2d();
  const float u_extra = rng.next_float();
  d.es = sample_emitter(scene.emitters[d.emitter], scene.shapes, si.p, u, u_extra);
  if (!(d.es.pdf > 0.0f) || is_black(d.es.radiance)) return d;
  d.wo_local = si.frame.to_local(d.es.wi);
  // Shading-normal light leaks: the geometric and shading hemispheres must agree.
  if (glm::dot(d.es.wi, si.ng) * d.wo_local.z <= 0.0f) return d;
  d.f = bsdf.eval(wi_local, d.wo_local, si.uv, front);
  if (is_black(d.f)) return d;
  counters.rays++;
  if (scene.occluded(d.es.to_infinity ? spawn_ray(si, d.es.wi) : spawn_ray_to(si, d.es.p))) return d;
  d.pdf_light = d.es.pdf * scene.emitter_selection_pdf();
  d.mis = d.es.delta || !scene.integrator.bsdf_sampling ? 1.0f : mis_power(d.pdf_light, bsdf.pdf(wi_local, d.wo_local, si.uv, front));
  d.ok = true;
  return d;
}

float russian_roulette(const Spectrum& beta, float eta_scale, Pcg32& rng) {
  // On the throughput with the radiance scaling of refraction removed.
  const float q = std::min(max_component(beta) * eta_scale, 0.95f);
  return rng.next_float() < q ? q : 0.0f;
}

Spectrum path_radiance(const Scene& scene, const Ray& camera_ray, Pcg32& rng, PathCounters& counters, const PathLimits& limits) {
  const IntegratorSettings& cfg = scene.integrator;
  const int max_depth = limits.max_depth;
  const bool hide = cfg.hide_emitters && limits.camera_ray;
  if (max_depth == 0) return Spectrum(0.0f);  // Mitsuba: no segments, no light
  Spectrum L(0.0f), beta(1.0f);
  Ray ray = camera_ray;
  float prev_pdf = 0.0f;    // solid-angle pdf of the BSDF sample that produced `ray`
  bool prev_delta = true;   // camera rays and delta lobes are not MIS-weighted
  Vec3 prev_p(0.0f);
  float eta_scale = 1.0f;   // product of eta^2 crossings, undoes radiance scaling inside RR

  for (int depth = 0;; ++depth) {
    SurfaceInteraction si;
    counters.rays++;
    if (depth == 0 && limits.first_hit) {
      si = *limits.first_hit;
    } else if (!scene.intersect(ray, si)) {
      if (depth == 0 && hide) break;
      for (int idx : scene.infinite_emitters) {
        const Emitter& e = scene.emitters[idx];
        const Spectrum Le = eval_infinite(e, ray.d);
        const float w = prev_delta || !cfg.emitter_sampling ? 1.0f : mis_power(prev_pdf, pdf_infinite(e, ray.d) * scene.emitter_selection_pdf());
        L += beta * Le * w;
      }
      break;
    }

    // Emission from an area emitter that was hit.
    if (emits_towards(scene, si, ray.d) && !(depth == 0 && hide)) {
      float w = 1.0f;
      if (!prev_delta && cfg.emitter_sampling) {
        const int ei = scene.shapes[si.shape].emitter;
        const float pdf_light = pdf_emitter_area(scene.emitters[ei], scene.shapes[si.shape], prev_p, si.p, si.ng) *
                                scene.emitter_selection_pdf();
        w = mis_power(prev_pdf, pdf_light);
      }
      L += beta * area_radiance(scene, si) * w;
    }

    // A path of depth + 2 segments is the next one NEE or BSDF sampling would make.
    if (max_depth >= 0 && depth + 2 > max_depth) break;

    const Shape& shape = scene.shapes[si.shape];
    const Bsdf& bsdf = scene.bsdfs[shape.bsdf];
    const Vec3 wi_local = si.frame.to_local(-ray.d);
    const bool front = glm::dot(ray.d, si.ng) < 0.0f;  // geometric side the ray arrives from

    // Next-event estimation.
    if (cfg.emitter_sampling && !bsdf.is_delta() && !scene.emitters.empty()) {
      const DirectLightSample d = sample_direct_light(scene, si, bsdf, wi_local, front, rng, counters);
      if (d.ok) L += beta * d.f * d.es.radiance * (d.mis / d.pdf_light);
    }
    if (!cfg.bsdf_sampling) break;

    const float u_lobe = rng.next_float();
    const auto bs = bsdf.sample(wi_local, u_lobe, rng.next_2d(), si.uv, front);
    if (!bs) break;
    const Vec3 wo = si.frame.to_world(bs->wo);
    if (glm::dot(wo, si.ng) * bs->wo.z <= 0.0f) break;  // shading-normal leak
    beta *= bs->weight;
    prev_pdf = bs->pdf;
    prev_delta = bs->delta;
    prev_p = si.p;
    eta_scale *= bs->eta * bs->eta;
    ray = spawn_ray(si, wo);

    if (depth + 1 >= cfg.rr_depth) {
      const float q = russian_roulette(beta, eta_scale, rng);
      if (q == 0.0f) break;
      beta /= q;
    }
    if (is_black(beta)) break;
  }
  return L;
}

}  // namespace limn
