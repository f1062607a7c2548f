// Unidirectional path tracer with next-event estimation and multiple importance sampling (power
// heuristic), Russian roulette and Mitsuba's max_depth convention. The `direct` integrator is this
// estimator with max_depth = 2 and no Russian roulette.
#pragma once
#include "core/math/rng.h"
#include "core/render/emitters/emitter.h"
#include "core/render/scene.h"

namespace limn {

struct PathCounters {
  uint64_t rays = 0;     // intersection and shadow rays traced
};

// Where a path starts and how long it may grow (segments, Mitsuba's max_depth; -1 unbounded).
// hide_emitters applies to camera rays only.
struct PathLimits {
  int max_depth;
  bool camera_ray;
  // When set, the ray's first hit, chosen by the caller (a surface the ray meets at a shared edge).
  const SurfaceInteraction* first_hit = nullptr;
};

// One next-event-estimation sample at si (an emitter chosen uniformly, a point or direction on it,
// the leak, BSDF and shadow tests). The primal path tracer and the derivative replay both call
// this, so they consume random numbers and reject samples identically.
struct DirectLightSample {
  bool ok = false;         // the sample contributes
  size_t emitter = 0;
  EmitterSample es;
  Vec3 wo_local{0.0f};     // es.wi in the shading frame
  Spectrum f{0.0f};        // bsdf.eval(wi, wo) (f |cos wo|)
  float pdf_light = 0.0f;  // es.pdf times the emitter selection probability
  float mis = 0.0f;        // MIS weight against BSDF sampling (1 for delta emitters)
};
DirectLightSample sample_direct_light(const Scene& scene, const SurfaceInteraction& si, const Bsdf& bsdf, const Vec3& wi_local,
                                      bool front, Pcg32& rng, PathCounters& counters);

// Russian roulette from the path's primal throughput: the survival probability, or 0 when the
// path ends (consumes one random number).
float russian_roulette(const Spectrum& beta, float eta_scale, Pcg32& rng);

// Radiance arriving along `ray` (towards its origin).
Spectrum path_radiance(const Scene& scene, const Ray& ray, Pcg32& rng, PathCounters& counters, const PathLimits& limits);

// Radiance arriving at the camera along a camera ray, with the scene's integrator settings.
inline Spectrum path_radiance(const Scene& scene, const Ray& ray, Pcg32& rng, PathCounters& counters) {
  return path_radiance(scene, ray, rng, counters, PathLimits{scene.integrator.max_depth, true});
}

}  // namespace limn
