#include "core/guiding/mixture.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace limn {

GuideMixture::GuideMixture(std::shared_ptr<const BoundaryGuide> first, std::shared_ptr<const BoundaryGuide> second, float w)
    : m_first(std::move(first)), m_second(std::move(second)), m_w(w) {
  if (!m_first || !m_second) throw std::invalid_argument("guide mixture: both guides are needed");
  if (!(w > 0.0f && w < 1.0f)) throw std::invalid_argument("guide mixture: the weight must be in (0, 1) (got " + std::to_string(w) + ")");
}

Vec3 GuideMixture::sample(const Vec3d& u, float* pdf) const {
  // The first number picks the component and is reused, rescaled (and kept below 1 against
  // rounding), inside it.
  const double below_one = std::nextafter(1.0, 0.0), w = m_w;
  float unused;
  const Vec3 p = u.x < w ? m_second->sample(Vec3d(std::min(u.x / w, below_one), u.y, u.z), &unused)
                         : m_first->sample(Vec3d(std::min((u.x - w) / (1.0 - w), below_one), u.y, u.z), &unused);
  *pdf = this->pdf(p);
  return p;
}

float GuideMixture::pdf(const Vec3& p) const { return (1.0f - m_w) * m_first->pdf(p) + m_w * m_second->pdf(p); }

float GuideMixture::pdf_first(float p0) const { return (1.0f - m_w) * m_first->pdf_first(p0) + m_w * m_second->pdf_first(p0); }

double GuideMixture::region_probability(size_t r) const {
  return (1.0 - m_w) * m_first->region_probability(r) + m_w * m_second->box_probability(m_first->region_box(r));
}

double GuideMixture::box_probability(const Box& box) const {
  return (1.0 - m_w) * m_first->box_probability(box) + m_w * m_second->box_probability(box);
}

std::string GuideMixture::describe() const {
  return m_first->describe() + ", mixed " + std::to_string(int(m_w * 100.0f + 0.5f)) + " % with the " + m_second->describe();
}

}  // namespace limn
