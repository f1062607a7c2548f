// Discontinuity search along a vertical slice of a heightfield (heightfield paper, section 2.3 and
// Algorithm 1). From an origin o (local frame) looking along the horizontal unit direction d, a
// surface point at horizontal distance t has slope k(t) = (z(o + t d) - o_z) / t. The directions in
// which visibility jumps are the slopes of the points that are local maxima of k and higher than
// every k before them (Eq. 12: the line from o is tangent there and the surface is concave), plus
// the far edge of the footprint when k still rises there, plus the near edge when o is outside the
// footprint. Everything below the running maximum slope is hidden, so mipmap nodes whose maximum
// height lies under the line o_z + k_run t are skipped (Eq. 13, Fig. 6).
// Curvature tests (limn's additions): near an origin on the surface that bound never holds, since
// the surface rises along its tangent plane as fast as the line, and where the slope k rises (the
// visible run before a peak, a pixel's footprint seen from the camera) every cell is a record; so
// every cell there was sampled and cells per sample grew with the side length. With the node's
// bound C on the second derivative along d, the surface over the node's span [t0, t1] lies under
// the parabola z(t0) + z'(t0) s + C s^2 / 2 and its slope above z'(t0) - C s (s = t - t0). A node is
// skipped as hidden when that parabola stays under the line, and is passed over to its far end when
// the bounds prove dk/dt > 0 throughout (no maximum inside).
#pragma once
#include <vector>
#include "core/geometry/shapes/heightfield/heightfield.h"

namespace limn {

struct SlicePeak {
  double t;      // horizontal distance from the origin
  double k;      // slope of the line from the origin to the peak
  bool border;   // a footprint edge, not a tangent point
};

struct PeakSearchStats {
  uint64_t nodes = 0;   // mipmap nodes visited
  uint64_t cells = 0;   // level-0 cells sampled
  uint64_t curvature_hidden = 0;  // nodes skipped by the curvature test: under the line
  uint64_t curvature_rising = 0;  // ... or with k rising throughout (no maximum inside)
};

struct PeakSearchOptions {
  bool use_mipmap = true;   // false: march every cell (the brute-force search, for comparison)
  int samples_per_cell = 4; // k is sampled at this many sub-steps per cell crossing
  bool curvature_test = true;  // with the mipmap: also skip nodes by their second-derivative bound
};

// Peaks with k in (k_start, k_stop), in order of increasing t (and so of increasing k). k_start is
// the running maximum at t = 0: the slope of the tangent plane when o is on the surface (below it
// the surface hides everything), or the lowest slope of interest otherwise.
// The last peak has the largest slope of the whole slice: rays steeper than it leave the field
// without meeting it. `blocked` (optional) is set when some point reaches k_stop: then every ray
// of the range meets the field (the search stops there).
std::vector<SlicePeak> find_peaks(const Heightfield& hf, const Vec3d& o, const glm::dvec2& d, double k_start, double k_stop,
                                  const PeakSearchOptions& options = {}, PeakSearchStats* stats = nullptr,
                                  bool* blocked = nullptr);

// The same search for rays of one fixed direction (a directional light): along the slice from o in
// direction d the rays are the lines z = g + k_light t. A ray grazes the surface where
// g(t) = z(o + t d) - k_light t has a local maximum higher than every g before it (the ray is
// tangent there and above the surface before it); SlicePeak::k is then that g. The footprint's
// near edge (o outside the footprint) and far edge (g still rising) count as for find_peaks.
std::vector<SlicePeak> find_parallel_peaks(const Heightfield& hf, const Vec3d& o, const glm::dvec2& d, double k_light,
                                           const PeakSearchOptions& options = {}, PeakSearchStats* stats = nullptr);

}  // namespace limn
