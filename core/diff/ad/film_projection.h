// World points to film positions (pixels) of the pinhole camera: the inverse of
// Camera::generate_ray, templated for the AD tape, plus the camera-connection importance.
#pragma once
#include "core/diff/ad/ad.h"
#include "core/render/camera.h"

namespace limn {

struct FilmProjection {
  Mat4d camera_from_world;
  double W, H, tan_x, tan_y, near;
  double FW, FH, crop_x, crop_y;  // the whole film and the image's (crop window's) offset in it

  explicit FilmProjection(const Camera& c)
      : camera_from_world(c.world_from_camera.inverse_matrix()), W(c.width), H(c.height), tan_x(c.tan_half_x),
        tan_y(c.tan_half_y), near(c.near_clip), FW(c.film_width()), FH(c.film_height()), crop_x(c.crop_x), crop_y(c.crop_y) {}

  template <typename T>
  ad::V3<T> to_camera(const ad::V3<T>& p) const {
    const Mat4d& m = camera_from_world;
    return ad::V3<T>(T(m[0][0]) * p.x + T(m[1][0]) * p.y + T(m[2][0]) * p.z + T(m[3][0]),
                     T(m[0][1]) * p.x + T(m[1][1]) * p.y + T(m[2][1]) * p.z + T(m[3][1]),
                     T(m[0][2]) * p.x + T(m[1][2]) * p.y + T(m[2][2]) * p.z + T(m[3][2]));
  }
  template <typename T>
  void film(const ad::V3<T>& pc, T& fx, T& fy) const {
    fx = T(0.5 * FW) * (T(1.0) - pc.x / (pc.z * T(tan_x))) - T(crop_x);
    fy = T(0.5 * FH) * (T(1.0) - pc.y / (pc.z * T(tan_y))) - T(crop_y);
  }
  // d(film)/d(world point) applied to the world displacement dp, at camera-space point pc.
  glm::dvec2 film_derivative(const ad::V3<double>& pc, const ad::V3<double>& dp_world) const {
    const ad::V3<double> dpc = to_camera(dp_world) - to_camera(ad::V3<double>(0, 0, 0));
    return glm::dvec2(-0.5 * FW / tan_x * (dpc.x / pc.z - pc.x * dpc.z / (pc.z * pc.z)),
                      -0.5 * FH / tan_y * (dpc.y / pc.z - pc.y * dpc.z / (pc.z * pc.z)));
  }
  // Film position (pixels) of world point p; false when it is behind the near plane. Also the
  // measurement's Jacobian from surface area at p (with geometric cosine cos_p towards the camera)
  // to film area in pixels: K^2 |cos_p| / (r^2 cos^3 theta), K = pixels per unit at z = 1.
  bool film_position(const Vec3& p, double cos_p, glm::dvec2& f, double& area_to_film) const {
    const ad::V3<double> pc = to_camera(ad::V3<double>(p.x, p.y, p.z));
    if (pc.z <= near) return false;
    film(pc, f.x, f.y);
    const double r2 = ad::dot(pc, pc);
    const double cos_t = pc.z / std::sqrt(r2);
    const double K = 0.5 * FW / tan_x;
    area_to_film = K * K * std::abs(cos_p) / (r2 * cos_t * cos_t * cos_t);
    return true;
  }
};

}  // namespace limn
