#include "core/render/camera.h"

#include <stdexcept>

namespace limn {

void Camera::set_fov(float fov_degrees, const std::string& fov_axis) {
  if (!(fov_degrees > 0.0f && fov_degrees < 180.0f))
    throw std::invalid_argument("fov must be in (0, 180) degrees (got " + std::to_string(fov_degrees) + ")");
  const float t = std::tan(0.5f * fov_degrees * kPi / 180.0f);
  const float w = float(width), h = float(height);
  std::string axis = fov_axis;
  if (axis == "smaller") axis = w <= h ? "x" : "y";
  if (axis == "larger") axis = w >= h ? "x" : "y";
  if (axis == "x") {
    tan_half_x = t;
    tan_half_y = t * h / w;
  } else if (axis == "y") {
    tan_half_y = t;
    tan_half_x = t * w / h;
  } else if (axis == "diagonal") {
    const float diag = std::sqrt(w * w + h * h);
    tan_half_x = t * w / diag;
    tan_half_y = t * h / diag;
  } else {
    throw std::invalid_argument("fov_axis must be one of x, y, diagonal, smaller, larger (got '" + fov_axis + "')");
  }
}

}  // namespace limn
