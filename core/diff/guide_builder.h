// The indirect boundary term's guide for one render_forward / render_backward call: built from
// the options (the path-space baseline grid, the projective grid, the octree with its training
// round; core/guiding/), or reused from a GuideCache kept between calls.
#pragma once
#include <memory>
#include <string>
#include <vector>
#include "core/diff/diff_options.h"
#include "core/diff/terms/indirect.h"
#include "core/guiding/guide.h"
#include "core/math/sequence.h"

namespace limn {

// A guide kept between calls (optimisation iterations). It is reused while the guiding settings
// and the boundary sample space's layout are the same, for at most `guide_refresh` calls, and
// while no moving geometry has moved by more than `guide_refresh_threshold` of its bounding-box
// diagonal since the guide was built. A stale guide is still a valid density (the estimate stays
// unbiased), only less well matched.
struct GuideCache {
  std::shared_ptr<const BoundaryGuide> guide;
  std::string key;
  std::string origin;
  std::vector<float> geometry;  // moving geometry when the guide was built
  float extent = 0.0f;          // its bounding-box diagonal
  int uses = 0;
  double build_seconds = 0.0;
  uint64_t builds = 0, reuses = 0;
};

// Point j of a call's n points of the boundary sample space [0,1)^3, as boundary_sampler says:
// stratified (core/math/sequence.h) or independent.
class BoundaryPoints {
 public:
  BoundaryPoints(const DiffOptions& opt, uint64_t n, uint64_t tag)
      : m_stratify(opt.boundary_sampler == "stratified"), m_sequence(n, mix_bits(opt.seed ^ tag)) {}
  Vec3d operator()(uint64_t j, Pcg32& rng) const {
    return m_stratify ? m_sequence.point(j, rng) : Vec3d(rng.next_double(), rng.next_double(), rng.next_double());
  }

 private:
  bool m_stratify;
  StratifiedSequence3 m_sequence;
};

// The guide a call samples with, and what the summary says of it.
struct CallGuide {
  std::shared_ptr<const BoundaryGuide> guide;
  double seconds = 0.0;
  std::string origin;  // how the guide was filled
  std::string reuse;   // what the cache did
};

// Builds the guide for options.guiding ("grid" or "octree"), or reuses the cached one
// (options.guide_cache, GuideCache's rules).
CallGuide guide_for_call(const Scene& scene, const DiffParams& params, const IndirectBoundary& indirect, const DiffOptions& options);

// The indirect term's guide as render_forward builds it for `options` (guiding "grid" or
// "octree"), and the line saying how it was filled: for tools that study the guides
// (tests/bench/guide_variance.cpp).
std::shared_ptr<const BoundaryGuide> build_boundary_guide(const Scene& scene, const IndirectBoundary& indirect,
                                                          const DiffOptions& options, std::string* origin = nullptr);

}  // namespace limn
