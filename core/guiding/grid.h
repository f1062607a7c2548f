// Uniform grid guiding over a 3D boundary sample space [0,1)^3 (the path-space baseline of the
// projective-sampling paper, section 5.1.1, without projection): every cell's mass is estimated
// from `samples_per_cell` random points, cells are then sampled in proportion to it, mixed with a
// defensive uniform component so that no region has zero probability (the estimate stays
// unbiased wherever the integrand is non-zero).
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include "core/math/distribution.h"
#include "core/math/vec.h"

namespace limn {

class BoundaryGrid {
 public:
  // integrand(u) >= 0 at a point of [0,1)^3; called from several threads at once.
  BoundaryGrid(std::array<int, 3> resolution, int samples_per_cell, uint64_t seed, int threads,
               const std::function<float(const Vec3&)>& integrand, float defensive = 0.1f);

  // A point of [0,1)^3 from three uniform numbers, and its density with respect to [0,1)^3.
  Vec3 sample(const Vec3& u, float* pdf) const;
  float pdf(const Vec3& p) const;
  // Density of the first coordinate alone (for terms that only use it).
  float pdf_first(float p0) const;

  size_t cell_count() const { return m_mass.size(); }
  size_t empty_cells() const { return m_empty; }

 private:
  size_t cell_of(const Vec3& p) const;
  std::array<int, 3> m_res;
  std::vector<float> m_mass;     // mixture probability of each cell
  std::vector<float> m_first;    // marginal probability of each slice along the first axis
  Distribution1D m_cells;
  size_t m_empty = 0;
};

}  // namespace limn
