// Pinhole perspective camera (Mitsuba's `perspective` sensor). Camera space: +z looks forward,
// +y is up, +x points to the left of the image, so image x grows towards -x.
#pragma once
#include <string>
#include "core/geometry/ray.h"
#include "core/geometry/transform.h"

namespace limn {

struct Camera {
  Transform world_from_camera;
  int width = 256, height = 256;
  float tan_half_x = 0.0f, tan_half_y = 0.0f;  // half extents of the image plane at z = 1
  float near_clip = 1e-2f, far_clip = 1e4f;

  // fov in degrees along `fov_axis`: "x", "y", "diagonal", "smaller" or "larger".
  void set_fov(float fov_degrees, const std::string& fov_axis);

  // Ray through film position (x, y) in pixels, (0, 0) the top-left corner of the image.
  Ray generate_ray(const Vec2& film) const {
    const Vec3 d_cam = glm::normalize(Vec3((1.0f - 2.0f * film.x / width) * tan_half_x,
                                           (1.0f - 2.0f * film.y / height) * tan_half_y, 1.0f));
    Ray r;
    r.o = world_from_camera.point(Vec3(0.0f));
    r.d = glm::normalize(world_from_camera.vector(d_cam));
    r.tmin = near_clip / d_cam.z;
    r.tmax = far_clip / d_cam.z;
    return r;
  }
};

}  // namespace limn
