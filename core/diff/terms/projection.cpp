#include "core/diff/terms/projection.h"

#include <map>
#include "core/diff/shapes/all.h"

namespace limn {

Projector::Projector(const Scene& scene, const BoundarySpace& space, MeshProjection mode) {
  std::map<int, std::vector<int>> segments_of;  // shape -> its segments
  const auto& segs = space.segments();
  for (size_t i = 0; i < segs.size(); ++i) segments_of[segs[i].shape].push_back(int(i));
  for (const auto& [shape, segments] : segments_of)
    m_shapes[shape] = with_group<BoundarySegments, std::unique_ptr<ShapeProjector>>(
        scene, shape, "boundary segments",
        [&, shape = shape](auto group, const auto& g) { return group.projector(scene, g, space, shape, segments, mode); });
}

Projector::~Projector() = default;

std::optional<Projection> Projector::project(const Vec3& xa, const SurfaceInteraction& hit, Pcg32& rng) const {
  if (!hit.valid()) return std::nullopt;
  auto it = m_shapes.find(hit.shape);
  if (it == m_shapes.end()) return std::nullopt;
  return it->second->project(xa, hit, rng);
}

}  // namespace limn
