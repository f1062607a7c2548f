// Guiding seeds for projective sampling (projective-sampling paper, section 3.1 and Figure 9):
// ordinary path segments from primal-style paths (camera ray, then BSDF sampling), taken from BSDF
// sampling, from emitter sampling (the shadow ray's first blocker) or both, projected onto the
// silhouettes of the shapes they end on.
#pragma once
#include <string>
#include <vector>
#include "core/diff/terms/projection.h"

namespace limn {

enum class SeedSegments { Bsdf, Emitter, Both };
SeedSegments parse_seed_segments(const std::string& name, const std::string& source);

struct SeedStats {
  uint64_t paths = 0, segments = 0, projected = 0, found = 0, rays = 0;
};

// Projections of the segments of `paths` seed paths, in a thread-count independent order.
// max_depth as IntegratorSettings::max_depth bounds the path length (at most 3 vertices after
// the camera are used for seeds).
std::vector<Projection> projected_seeds(const Scene& scene, const Projector& projector, uint64_t paths, SeedSegments which,
                                        int max_depth, uint64_t seed, int threads, SeedStats* stats);

}  // namespace limn
