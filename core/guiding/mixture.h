// A one-sample mixture of two guides, (1 - w) p_first + w p_second, each with its own defensive
// uniform share (so the mixture keeps one too). limn uses it to mix the octree with the projective
// grid filled from the same projections: the octree's deep leaves hold the mass of the points
// that were found, while the grid's coarse cells also cover the rest of the narrow feature those
// points sample (a near-specular lobe's ridge along a silhouette) that the leaves next to them
// estimate as empty from a few uniform points; and either projective guide with the histogram of
// the projections' directions (DiffOptions::direction_mix). Measured in docs/reports/projective/README.md.
#pragma once
#include <memory>
#include "core/guiding/guide.h"

namespace limn {

class GuideMixture : public BoundaryGuide {
 public:
  GuideMixture(std::shared_ptr<const BoundaryGuide> first, std::shared_ptr<const BoundaryGuide> second, float second_weight);

  Vec3 sample(const Vec3d& u, float* pdf) const override;
  float pdf(const Vec3& p) const override;
  float pdf_first(float p0) const override;
  size_t memory_bytes() const override { return m_first->memory_bytes() + m_second->memory_bytes(); }
  std::string describe() const override;
  // Regions are the first guide's; their probabilities integrate the second guide over them.
  size_t region_count() const override { return m_first->region_count(); }
  size_t region_of(const Vec3& p) const override { return m_first->region_of(p); }
  double region_probability(size_t region) const override;
  Box region_box(size_t region) const override { return m_first->region_box(region); }
  double box_probability(const Box& box) const override;

 private:
  std::shared_ptr<const BoundaryGuide> m_first, m_second;
  float m_w;
};

}  // namespace limn
