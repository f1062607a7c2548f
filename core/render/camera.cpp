#include "core/render/camera.h"

#include <stdexcept>

namespace limn {

void Camera::set_fov(float fov_degrees, const std::string& fov_axis) {
  if (!(fov_degrees > 0.0f && fov_degrees < 180.0f))
    throw std::invalid_argument("fov must be in (0, 180) degrees (got " + std::to_string(fov_degrees) + ")");
  const float t = std::tan(0.5f * fov_degrees * kPi / 180.0f);
  const float w = float(film_width()), h = float(film_height());
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

double FilmFilter::eval(double x) const {
  if (type == Type::Box) return x >= -0.5 && x < 0.5 ? 1.0 : 0.0;
  const double a = -0.5 / (stddev * stddev);
  return std::max(0.0, std::exp(a * x * x) - std::exp(a * radius * radius));
}

double FilmFilter::integral() const {
  if (type == Type::Box) return 1.0;
  const double a = -0.5 / (stddev * stddev);
  return stddev * std::sqrt(2.0 * M_PI) * std::erf(radius / (stddev * std::sqrt(2.0))) - 2.0 * radius * std::exp(a * radius * radius);
}

double FilmFilter::sample(double u) const {
  if (type == Type::Box) return u - 0.5;
  // Invert the CDF, (G(x) - G(-r) - b (x + r)) / Z with G the Gaussian's antiderivative, by Newton
  // steps kept inside a bisection bracket (the density is 0 only at the ends).
  const double s2 = stddev * std::sqrt(2.0), b = std::exp(-0.5 * radius * radius / (stddev * stddev));
  const double half_root_pi = 0.5 * std::sqrt(M_PI) * s2, Z = integral();
  auto cdf = [&](double x) { return (half_root_pi * (std::erf(x / s2) + std::erf(radius / s2)) - b * (x + radius)) / Z; };
  const double target = std::min(std::max(u, 0.0), 1.0);
  double lo = -radius, hi = radius, x = 0.0;
  for (int i = 0; i < 60; ++i) {
    const double c = cdf(x) - target;
    if (c > 0.0) hi = x;
    else lo = x;
    const double d = eval(x) / Z;
    double next = d > 0.0 ? x - c / d : 0.5 * (lo + hi);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::abs(next - x) < 1e-12 * radius) return next;
    x = next;
  }
  return x;
}

}  // namespace limn
