// The heightfield derivative estimator (Tong et al. 2023, section 2.2, Eq. 10-11, App. A-C), used
// by render_forward / render_backward when the scene holds a heightfield and geometry is
// differentiable. Every direction is sampled in global spherical coordinates around the
// heightfield's up axis: an azimuth phi, then theta in the theta-range of the domain (pixel, area
// emitter, or the hemisphere above the local tangent plane). The range is split at every
// discontinuity along that vertical slice (peak_search.h, emitter edges, footprint edges); the
// camera traces every interval (camera_every_interval), other vertices choose one (by width with a
// uniform share, which bounds the reciprocal pdf at slivers); theta is the linear map of the
// interval's end points,
// which are taped functions of the heights, so their motion enters through the reciprocal pdf and
// no boundary integral is needed. Vertices reached along these directions slide on their ray.
//
// Strategies per vertex (a partition, no MIS, so the derivative of each stays unbiased):
//   * area emitters only through emitter-domain sampling (App. A.1), one emitter chosen uniformly;
//   * point and directional lights by a shadow ray; their shadow edges cast by the heightfields
//     by a boundary term splatted to the film (delta_edge_sample); other occluders' shadow edges
//     are NOT differentiated (named in the summary);
//   * everything else by uniform phi and theta over the continuation range (App. A.2), which
//     ignores area-emitter emission; escaping rays pick up infinite emitters.
// The camera ray is the pixel domain in the same coordinates (App. A.1). Several heightfields may
// share a scene when their up axes are parallel: the coordinates are the first one's, and every
// slice is split at each field's peaks (docs/heightfields.md). Discontinuities caused by
// other occluders than heightfields and emitters (meshes and spheres without emission) are not
// split; rays that hit them are counted (other_shape_hits), since they can bias the estimate.
#pragma once
#include <memory>
#include <string>
#include <vector>
#include "core/diff/ad/diff_params.h"
#include "core/geometry/shapes/heightfield/peak_search.h"
#include "core/math/rng.h"

namespace limn {

struct HeightfieldOptions {
  PeakSearchOptions search;
  // Appendix C: split each theta range into sub-ranges of at most this many degrees and search
  // only the one holding the sample (faster, noisier). 0: search the whole range.
  float theta_subrange_degrees = 0.0f;
  // false: split points are held at their primal values (their motion is dropped), which leaves
  // only the continuous part of the derivative: for tests that show what the reparameterisation adds.
  bool reparameterize = true;
  // Share of the interval choice made uniformly over the intervals (the rest is proportional to
  // their widths); see choose_interval in estimator.cpp.
  float interval_uniform_share = 0.5f;
  // Camera rays: trace every interval of the pixel's theta range (Eq. 5, one path each) instead of
  // choosing one (Eq. 6). Only pixels holding a split cost more (a path per interval); on the cone
  // the summed per-pixel variance fell 7.7-8x at the same time per call, on the terrain it is the same.
  bool camera_every_interval = true;
  // The boundary term of point and directional lights' shadow edges cast by heightfields (delta_edge_sample).
  bool delta_edges = true;
};

// One film splat of a boundary sample: value times the derivative of velocity[velocity].
struct HeightfieldSplat {
  int pixel;
  Spectrum value;
  int velocity;
};

struct HeightfieldCounters {
  uint64_t rays = 0;
  uint64_t searches = 0;            // peak searches
  PeakSearchStats search;           // their mipmap nodes and cells
  uint64_t other_shape_hits = 0;    // rays that met an occluder whose edges are not split
  uint64_t delta_light_samples = 0; // shadow rays to point / directional lights
  uint64_t empty_ranges = 0;        // pixel or emitter samples whose theta-range was empty (value 0)
  uint64_t edge_samples = 0;        // point / directional light shadow edge samples (delta_edge_sample)
  uint64_t edge_splats = 0;         // ... that reached the film
  uint64_t other_shadow_blocks = 0; // shadow rays to delta lights blocked by a shape that is no heightfield
  std::vector<char> shadow_blockers;  // per shape: 1 if it blocked one of them
  void add(const HeightfieldCounters& o);
};

class HeightfieldEstimator {
 public:
  // Throws std::invalid_argument (naming the scene and object) for scenes the estimator cannot
  // treat: heightfields whose up axes differ, delta or transmissive BSDFs, moving shapes other than
  // heightfields and area emitters, sphere emitters.
  HeightfieldEstimator(const Scene& scene, const DiffParams& params, const HeightfieldOptions& options, int max_depth);

  // One sample of pixel (x, y) (box filter) as taped RGB.
  ad::V3<ad::Var> pixel(int x, int y, Pcg32& rng, PathInputs& in, HeightfieldCounters& counters) const;

  int heightfield_shape() const { return m_shape; }

  // Point and directional lights' shadow edges cast by the heightfields: a boundary term
  // splatted to the film, since those edges are not split points of the slices the estimator
  // samples. One sample: a light, a field, a slice u (uniform): for a point light the azimuth
  // around it, for a directional light the offset of a vertical slice along its direction,
  // across the footprint. Every peak of that slice as the light sees it (find_peaks from the
  // point, find_parallel_peaks along the direction) is a grazing ray (Eq. 12: its slope or
  // intercept's derivative is the partial at fixed t); the ray continues to the receiver y, seen
  // directly by the camera. Adds to the film point of y: (f(s - delta n) - f(s + delta n))
  // |ds/du| / pdf times d(s . n), n the film normal of the edge. Values are per sample (the
  // caller divides by the count). False: nothing added.
  bool delta_edge_sample(Pcg32& rng, PathInputs& in, std::vector<HeightfieldSplat>& splats, std::vector<ad::Var>& velocity,
                         HeightfieldCounters& counters) const;
  bool has_delta_edges() const { return m_opt.delta_edges && m_opt.reparameterize && !m_edge_lights.empty(); }
  // What the estimator computed and left out, for DiffStats::summary.
  std::vector<std::string> summary(int spp, const HeightfieldCounters& counters) const;

 private:
  struct EmitterTriangles {
    int emitter, shape;
    std::vector<int> prims;
  };
  const Scene& m_scene;
  const DiffParams& m_params;
  HeightfieldOptions m_opt;
  int m_max_depth;
  int m_shape = -1;             // the first heightfield: its local frame holds the spherical coordinates
  std::vector<int> m_shapes;    // every heightfield (m_shape first); all share the up axis
  std::vector<EmitterTriangles> m_area_emitters;
  std::vector<int> m_delta_emitters;
  std::vector<int> m_edge_lights;  // point lights and directional lights from above (delta_edge_sample)

  friend struct HeightfieldPath;
};

// The heightfield estimator when the scene holds a heightfield and geometry is differentiable (it
// then replaces the interior and both boundary terms), else null. spp: paths per pixel; 0 is
// refused, since the estimator has no separate boundary term.
std::unique_ptr<HeightfieldEstimator> heightfield_estimator(const Scene& scene, const DiffParams& params, const HeightfieldOptions& options,
                                                            int max_depth, int spp);

}  // namespace limn
