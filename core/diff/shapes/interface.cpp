#include "core/diff/shapes/interface.h"

namespace limn {

namespace {
// Not inlined: Debian's g++ 12.2 (-O2, -O3) vectorises the float -> double widening of a freshly
// transformed point and drops the rounding to float in between, so eye would not be the camera
// rays' (float) origin.
[[gnu::noinline]] ad::V3<double> widen(const Vec3& v) { return ad::V3<double>(v.x, v.y, v.z); }
}  // namespace

std::optional<Projection> finish_projection(const SegmentSpace& space, int segment, const Vec3& xa, const Vec3& xb, bool found,
                                            const Vec3& w_first) {
  for (const Vec3& d : {w_first, xa - xb}) {
    if (!(glm::length(d) > 0.0f) || !std::isfinite(d.x + d.y + d.z)) continue;
    const Vec3 w = glm::normalize(d);
    const Vec3 u = space.invert(segment, xb, w);
    BoundaryPoint check;
    if (space.sample(u, 1.0f, check) && check.segment == segment) return Projection{u, segment, check.xb, check.w, found};
  }
  return std::nullopt;  // neither direction sees a silhouette there
}

CameraView::CameraView(const Camera& c) : proj(c), eye_world(c.world_from_camera.point(Vec3(0.0f))), eye(widen(eye_world)) {}

}  // namespace limn
