// Uniform grid guiding over the boundary sample space [0,1)^3 (projective-sampling paper, section
// 5.1.1). Two ways to fill it: the path-space baseline estimates every cell's mass from
// `samples_per_cell` random points; the projective grid accumulates the integrand at projected
// samples (points found by projecting path segments onto silhouettes) into their cells. Cells are
// sampled in proportion to their mass, mixed with a defensive uniform component.
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include <vector>
#include "core/guiding/guide.h"
#include "core/math/distribution.h"

namespace limn {

class BoundaryGrid : public BoundaryGuide {
 public:
  // Baseline: integrand(u) >= 0 at a point of [0,1)^3; called from several threads at once.
  BoundaryGrid(std::array<int, 3> resolution, int samples_per_cell, uint64_t seed, int threads,
               const std::function<float(const Vec3&)>& integrand, float defensive = 0.1f);
  // Projective: the integrand's values at projected points accumulate into their cells.
  BoundaryGrid(std::array<int, 3> resolution, const std::vector<Vec3>& points, const std::vector<float>& values,
               float defensive = 0.1f);

  Vec3 sample(const Vec3d& u, float* pdf) const override;
  float pdf(const Vec3& p) const override;
  float pdf_first(float p0) const override;
  size_t memory_bytes() const override { return m_mass.size() * 2 * sizeof(float) + m_cells.size() * sizeof(double); }
  std::string describe() const override;
  size_t region_count() const override { return m_mass.size(); }
  size_t region_of(const Vec3& p) const override { return cell_of(p); }
  double region_probability(size_t c) const override { return m_cells.pmf(c); }
  Box region_box(size_t c) const override;
  double box_probability(const Box& box) const override;

  size_t cell_count() const { return m_mass.size(); }
  const std::array<int, 3>& resolution() const { return m_res; }
  size_t empty_cells() const { return m_empty; }

  static constexpr int kMaxResolution = 4096;  // cells per axis
  static constexpr size_t kMaxCells = size_t(1) << 24;  // cells in all, 256 MiB

 private:
  static void check_resolution(const std::array<int, 3>& res);
  void finish(const std::vector<float>& mass, float defensive);
  size_t cell_of(const Vec3& p) const;
  std::array<int, 3> m_res;
  bool m_projective = false;
  std::vector<float> m_mass;     // mixture probability of each cell
  std::vector<float> m_first;    // marginal probability of each slice along the first axis
  Distribution1D m_cells;
  size_t m_empty = 0;
};

// The projective grid as a pyramid (not in the paper): grids of R 2^k x R/4 2^k x R/2 2^k cells for
// k = -coarser..finer, all filled from the same projections and sampled with equal shares. A
// projection costs one integrand evaluation whatever the cell size, so the fine levels add
// resolution at no evaluation cost (the narrow GGX lobe and thin shadows need it), while the
// coarse levels spread each projection's mass over the neighbourhood where the seed paths left
// gaps (docs/reports/projective/README.md). Finer levels over kMaxLevelCells are left out and
// describe() says so. The density is piecewise constant over the finest level's cells (its
// regions) when the levels' cells nest.
class GridPyramid : public BoundaryGuide {
 public:
  GridPyramid(std::array<int, 3> resolution, int coarser, int finer, const std::vector<Vec3>& points, const std::vector<float>& values,
              float defensive = 0.1f);

  Vec3 sample(const Vec3d& u, float* pdf) const override;
  float pdf(const Vec3& p) const override;
  float pdf_first(float p0) const override;
  size_t memory_bytes() const override;
  std::string describe() const override;
  size_t region_count() const override { return m_levels.back().region_count(); }
  size_t region_of(const Vec3& p) const override { return m_levels.back().region_of(p); }
  double region_probability(size_t c) const override { return box_probability(m_levels.back().region_box(c)); }
  Box region_box(size_t c) const override { return m_levels.back().region_box(c); }
  double box_probability(const Box& box) const override;

  size_t levels() const { return m_levels.size(); }
  static constexpr size_t kMaxLevelCells = size_t(1) << 22;  // 64 MiB per level

 private:
  std::vector<BoundaryGrid> m_levels;  // coarse to fine
  int m_left_out = 0;                  // finer levels over kMaxLevelCells
};

}  // namespace limn
