// Embree 3 acceleration structure over the scene's shapes; each kind registers its own Embree
// geometry (the shape interface, shape.h): triangle meshes as Embree triangles (refit when vertices
// move), spheres and heightfields as user geometry with their own intersectors.
#pragma once
#include <embree3/rtcore.h>
#include <atomic>
#include <memory>
#include <string>
#include <vector>
#include "core/geometry/shapes/shape.h"

namespace limn {

// Embree device shared by all scenes. Errors reported through Embree's callback are recorded
// (and counted) here; the edges of the core turn them into exceptions via check().
class EmbreeDevice {
 public:
  static RTCDevice get();
  // Throws std::runtime_error naming `what` if Embree reported an error since the last check.
  static void check(const std::string& what);
  static size_t error_count();
  static std::string last_error();
};

class Accel {
 public:
  explicit Accel(std::vector<Shape>& shapes);  // shapes must outlive the Accel and never be resized
  ~Accel();
  Accel(const Accel&) = delete;
  Accel& operator=(const Accel&) = delete;

  // Re-uploads the geometry of shape i after its parameters changed; commit() makes it visible.
  void shape_changed(int i);
  void commit();

  // Rays Embree cannot trace (a NaN, or an origin or direction component beyond FLT_LARGE) miss and
  // are counted: Embree asserts on them in debug builds and traverses garbage otherwise.
  bool intersect(const Ray& ray, SurfaceInteraction& si) const;
  bool occluded(const Ray& ray) const;
  uint64_t invalid_rays() const { return m_invalid_rays.load(std::memory_order_relaxed); }

 private:
  bool traceable(const Ray& ray) const;
  mutable std::atomic<uint64_t> m_invalid_rays{0};
  std::vector<Shape>& m_shapes;
  RTCScene m_scene = nullptr;
  std::vector<RTCGeometry> m_geoms;
};

}  // namespace limn
