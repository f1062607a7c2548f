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

// Radiance arriving at the camera along `ray`.
Spectrum path_radiance(const Scene& scene, const Ray& ray, Pcg32& rng, PathCounters& counters);

}  // namespace limn
