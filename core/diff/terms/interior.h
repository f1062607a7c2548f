// Interior (continuous) derivative term: each path of the primal path tracer is replayed with the
// same random numbers while its contribution is recorded on the AD tape, in the material form
// (docs/derivatives.md, "What is computed"): vertices sampled from a BSDF are attached to their
// surface (core/diff/shapes/: fixed barycentrics, sphere directions, grid coordinates), directions
// between vertices are recomputed from the attached positions and the change of variables
// |cos| / distance^2 (times the area Jacobian) is differentiated against its detached primal value. Vertices reached along rays that are not
// sampled (camera rays, delta reflection and refraction) slide along the differentiated ray.
// Sampling decisions, pdfs and MIS weights stay at their primal values.
#pragma once
#include "core/diff/ad/diff_params.h"
#include "core/math/rng.h"
#include "core/render/integrators/path.h"

namespace limn {

struct InteriorCounters {
  uint64_t paths = 0;
  uint64_t invalid = 0;  // paths whose value was not finite (dropped)
};

// Radiance along camera_ray as three tape variables (R, G, B); consumes random numbers exactly as
// path_radiance() does, so its value equals the primal estimate.
// max_depth: as IntegratorSettings::max_depth. horizon: at smooth-shaded vertices, add the boundary
// term of the leak test's cut at the geometric horizon (value 0, a derivative only; interior.cpp).
ad::V3<ad::Var> interior_path_radiance(const Scene& scene, const DiffParams& params, const Ray& camera_ray, Pcg32& rng,
                                       PathInputs& inputs, PathCounters& counters, int max_depth, bool horizon = true);

}  // namespace limn
