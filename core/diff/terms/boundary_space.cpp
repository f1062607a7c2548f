#include "core/diff/terms/boundary_space.h"

#include <algorithm>

#include "core/diff/shapes/all.h"

namespace limn {

BoundarySpace::BoundarySpace(const Scene& scene, const DiffParams& params, bool perimeter, bool interior)
    : m_scene(scene), m_params(params) {
  // Moving shapes first, then static ones: a static silhouette matters too when a segment grazing
  // it ends on a moving surface (a receiver moving under a static occluder).
  std::vector<int> order = params.moving_shapes();
  const size_t moving_count = order.size();
  for (size_t i = 0; i < scene.shapes.size(); ++i)
    if (!params.moves(int(i))) order.push_back(int(i));
  double moving_measure = 0.0, static_measure = 0.0;
  for (const BoundaryPart part : {BoundaryPart::Perimeter, BoundaryPart::Interior})
    for (size_t oi = 0; oi < order.size(); ++oi) {
      if (!(part == BoundaryPart::Perimeter ? perimeter : interior)) continue;
      const int si = order[oi];
      const bool moving = oi < moving_count;
      if (!has_group<BoundarySegments>(scene.shapes[si])) {
        if (!moving) {  // its silhouettes cannot be sampled: said in the summary
          if (part == BoundaryPart::Perimeter) m_left_out.push_back(scene.shapes[si].id);
          continue;
        }
        with_group<BoundarySegments>(scene, si, "boundary segments", [](auto, const auto&) {});  // throws, naming the shape
      }
      const size_t first = m_segments.size();
      with_group<BoundarySegments>(scene, si, "boundary segments",
                                   [&](auto group, const auto& g) { group.append(scene, g, si, moving, part, m_segments); });
      for (size_t k = first; k < m_segments.size(); ++k) (moving ? moving_measure : static_measure) += m_segments[k].weight;
    }
  // Static segments get at most a quarter of the samples: they contribute only where a moving
  // surface ends the segment, moving ones wherever they are seen.
  if (moving_measure > 0.0 && static_measure > 0.0) {
    const double scale = std::min(1.0, (0.25 / 0.75) * moving_measure / static_measure);
    for (BoundarySegment& s : m_segments)
      if (!s.moving) s.weight = float(s.weight * scale);
  }
  std::vector<float> weights;
  for (const BoundarySegment& s : m_segments) weights.push_back(s.weight);
  if (!weights.empty()) m_select = Distribution1D(weights);
}

size_t BoundarySpace::static_count() const {
  size_t n = 0;
  for (const BoundarySegment& seg : m_segments) n += !seg.moving;
  return n;
}

std::vector<std::pair<std::string, size_t>> BoundarySpace::segment_counts() const {
  std::vector<std::pair<std::string, size_t>> counts;
  for (const BoundarySegment& seg : m_segments) {
    const std::string name = with_group<BoundarySegments, const char*>(m_scene, seg.shape, "boundary segments",
                                                                       [](auto group, const auto&) { return group.segment_name; });
    auto it = std::find_if(counts.begin(), counts.end(), [&](const auto& c) { return c.first == name; });
    if (it == counts.end()) counts.push_back({name, 1});
    else it->second++;
  }
  return counts;
}

// The segment for u0 and the offset along it, kept below 1 after rounding to float.
float BoundarySpace::select(float u0, size_t* k) const { return float(std::min(m_select.sample_remapped(u0, k), 1.0 - 1e-7)); }

bool BoundarySpace::sample(const Vec3& u, float pdf_u, BoundaryPoint& out) const {
  size_t k;
  const float f = select(u.x, &k);
  const BoundarySegment& s = m_segments[k];
  out.segment = int(k);
  return with_group<BoundarySegments, bool>(m_scene, s.shape, "boundary segments", [&](auto group, const auto& g) {
    return group.sample(m_scene, g, s, f, u.y, u.z, pdf_u * m_select.pmf(k), out);
  });
}

Vec3 BoundarySpace::invert(int segment, const Vec3& xb, const Vec3& w) const {
  const BoundarySegment& s = m_segments[size_t(segment)];
  Vec3 u = with_group<BoundarySegments, Vec3>(m_scene, s.shape, "boundary segments",
                                              [&](auto group, const auto& g) { return group.invert(m_scene, g, s, xb, w); });
  u.x = m_select.invert_remapped(size_t(segment), u.x);
  return u;
}

bool BoundarySpace::sample_delta(float u0, float pdf_u0, const Emitter& light, BoundaryPoint& out) const {
  size_t k;
  const float f = select(u0, &k);
  const BoundarySegment& s = m_segments[k];
  out.segment = int(k);
  if (!light.is_delta()) return false;
  return with_group<BoundarySegments, bool>(m_scene, s.shape, "boundary segments", [&](auto group, const auto& g) {
    return group.sample_delta(m_scene, g, s, f, pdf_u0 * m_select.pmf(k), light, out);
  });
}

ad::V3<ad::Var> BoundarySpace::attached_point(const BoundaryPoint& p, PathInputs& in) const {
  const BoundarySegment& s = m_segments[size_t(p.segment)];
  const DiffContext c{m_scene, m_params, in};
  return with_group<BoundarySegments, ad::V3<ad::Var>>(m_scene, s.shape, "boundary segments",
                                                       [&](auto group, const auto& g) { return group.attached_point(c, g, s, p); });
}

}  // namespace limn
