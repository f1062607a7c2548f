// A guiding distribution over the boundary sample space [0,1)^3 (projective-sampling paper,
// section 5.1): a mixture with a defensive uniform component, so that every region keeps a
// non-zero density and the boundary estimate stays unbiased wherever the integrand is non-zero.
#pragma once
#include <algorithm>
#include <cstddef>
#include <string>
#include "core/math/vec.h"

namespace limn {

// An axis-aligned box of [0,1)^3: its low corner and its size.
struct Box {
  Vec3 lo, size;
};

// The fraction of `region`'s volume that lies inside `box`.
inline double overlap_fraction(const Box& region, const Box& box) {
  double f = 1.0;
  for (int a = 0; a < 3; ++a) {
    const double lo = std::max(region.lo[a], box.lo[a]), hi = std::min(region.lo[a] + region.size[a], box.lo[a] + box.size[a]);
    if (!(hi > lo)) return 0.0;
    f *= (hi - lo) / region.size[a];
  }
  return f;
}

class BoundaryGuide {
 public:
  virtual ~BoundaryGuide() = default;
  // A point of [0,1)^3 from three uniform numbers, and its density with respect to [0,1)^3.
  // u.x chooses the leaf, slab or a mixture's component (the grid: u.y and u.z its row and cell)
  // and its remainder places the point inside, so the numbers are doubles (Pcg32::next_double):
  // with a float's 24 bits a cell of probability p could only be reached at p 2^24 points along
  // an axis (a fixed quadrature instead of the density the guide reports).
  virtual Vec3 sample(const Vec3d& u, float* pdf) const = 0;
  virtual float pdf(const Vec3& p) const = 0;
  // Density of the first coordinate alone (for terms that only use it).
  virtual float pdf_first(float p0) const = 0;
  virtual size_t memory_bytes() const = 0;
  // The guide is piecewise constant over regions (cells, leaves): their number, the region that
  // holds p, and each one's probability (tests compare sampling frequencies with them).
  virtual size_t region_count() const = 0;
  virtual size_t region_of(const Vec3& p) const = 0;
  virtual double region_probability(size_t region) const = 0;
  virtual Box region_box(size_t region) const = 0;
  // The probability of a box (exact: the density is piecewise constant); O(regions), for tests
  // and mixtures' region probabilities, not for render loops.
  virtual double box_probability(const Box& box) const = 0;
  // One line for the run's summary: cells or leaves, empty ones, coarsening.
  virtual std::string describe() const = 0;
};

}  // namespace limn
