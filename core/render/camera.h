// Pinhole perspective camera (Mitsuba's `perspective` sensor). Camera space: +z looks forward,
// +y is up, +x points to the left of the image, so image x grows towards -x.
#pragma once
#include <algorithm>
#include <cmath>
#include <string>
#include "core/geometry/ray.h"
#include "core/geometry/transform.h"

namespace limn {

// The film's reconstruction filter (Mitsuba's `rfilter`), separable: a pixel's value is the
// radiance weighted by f(x) f(y) / (integral of f)^2, (x, y) in pixels from the pixel's centre.
struct FilmFilter {
  enum class Type { Box, Gaussian };
  Type type = Type::Box;
  double stddev = 0.5;  // gaussian, in pixels
  double radius = 0.5;  // half-width of the support: box 0.5, gaussian 4 stddev (Mitsuba's cut-off)

  // 1D weight: box 1 on [-1/2, 1/2); gaussian exp(-x^2 / 2 s^2) - exp(-r^2 / 2 s^2), clamped at 0
  // (Mitsuba's gaussian: shifted so that it reaches 0 at the radius).
  double eval(double x) const;
  double integral() const;        // of eval over [-radius, radius]
  double sample(double u) const;  // offset from the centre with density eval / integral (exact inverse CDF)
};

struct Camera {
  Transform world_from_camera;
  int width = 256, height = 256;               // the image: the crop window of the film
  int crop_x = 0, crop_y = 0;                  // the crop window's offset in the film (pixels)
  int full_width = 0, full_height = 0;         // the whole film, which the fov covers (0: width, height)
  float tan_half_x = 0.0f, tan_half_y = 0.0f;  // half extents of the whole film's image plane at z = 1
  float near_clip = 1e-2f, far_clip = 1e4f;
  FilmFilter filter;

  int film_width() const { return full_width > 0 ? full_width : width; }
  int film_height() const { return full_height > 0 ? full_height : height; }

  // fov in degrees along `fov_axis`: "x", "y", "diagonal", "smaller" or "larger" (of the whole film).
  void set_fov(float fov_degrees, const std::string& fov_axis);

  // Film position of a camera sample of pixel (x, y) from two uniform numbers: uniform over the
  // pixel (box), or the pixel's centre plus an offset drawn from the filter (filter importance
  // sampling: each sample has weight 1).
  Vec2 sample_film(int x, int y, const Vec2& u) const {
    if (filter.type == FilmFilter::Type::Box) return Vec2(float(x), float(y)) + u;
    return Vec2(float(x + 0.5 + filter.sample(u.x)), float(y + 0.5 + filter.sample(u.y)));
  }
  // Whether film position (fx, fy) reaches a pixel of the image through the filter.
  bool film_covers(double fx, double fy) const {
    if (filter.type == FilmFilter::Type::Box) return fx >= 0 && fx < width && fy >= 0 && fy < height;
    const double r = filter.radius;
    return fx > -r && fx < width + r && fy > -r && fy < height + r;
  }
  // Calls f(pixel index, weight) for each image pixel whose value a point at film position (fx, fy)
  // contributes to, weighted by the normalised filter (boundary terms' splats; the box: the pixel
  // that holds it, weight 1).
  template <typename F>
  void splat(double fx, double fy, F&& f) const {
    if (filter.type == FilmFilter::Type::Box) {
      if (fx >= 0 && fx < width && fy >= 0 && fy < height) f(int(fy) * width + int(fx), 1.0f);
      return;
    }
    const double r = filter.radius, norm = 1.0 / (filter.integral() * filter.integral());
    const int x0 = std::max(0, int(std::ceil(fx - 0.5 - r))), x1 = std::min(width - 1, int(std::floor(fx - 0.5 + r)));
    const int y0 = std::max(0, int(std::ceil(fy - 0.5 - r))), y1 = std::min(height - 1, int(std::floor(fy - 0.5 + r)));
    for (int y = y0; y <= y1; ++y) {
      const double wy = filter.eval(fy - (y + 0.5));
      if (wy <= 0.0) continue;
      for (int x = x0; x <= x1; ++x) {
        const double w = wy * filter.eval(fx - (x + 0.5)) * norm;
        if (w > 0.0) f(y * width + x, float(w));
      }
    }
  }

  // Ray through film position (x, y) in pixels, (0, 0) the top-left corner of the image (the crop
  // window's corner).
  Ray generate_ray(const Vec2& film) const {
    const Vec3 d_cam = glm::normalize(Vec3((1.0f - 2.0f * (film.x + float(crop_x)) / float(film_width())) * tan_half_x,
                                           (1.0f - 2.0f * (film.y + float(crop_y)) / float(film_height())) * tan_half_y, 1.0f));
    Ray r;
    r.o = world_from_camera.point(Vec3(0.0f));
    r.d = glm::normalize(world_from_camera.vector(d_cam));
    r.tmin = near_clip / d_cam.z;
    r.tmax = far_clip / d_cam.z;
    return r;
  }
};

}  // namespace limn
