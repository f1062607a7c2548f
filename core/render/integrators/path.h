// Unidirectional path tracer with next-event estimation and multiple importance sampling (power
// heuristic), Russian roulette and Mitsuba's max_depth convention. The `direct` integrator is this
// estimator with max_depth = 2 and no Russian roulette.
#pragma once
#include "core/math/rng.h"
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
};

// Radiance arriving along `ray` (towards its origin).
Spectrum path_radiance(const Scene& scene, const Ray& ray, Pcg32& rng, PathCounters& counters, const PathLimits& limits);

// Radiance arriving at the camera along a camera ray, with the scene's integrator settings.
inline Spectrum path_radiance(const Scene& scene, const Ray& ray, Pcg32& rng, PathCounters& counters) {
  return path_radiance(scene, ray, rng, counters, PathLimits{scene.integrator.max_depth, true});
}

}  // namespace limn
