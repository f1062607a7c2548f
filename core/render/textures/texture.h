// Spectrum-valued textures: a constant or a bitmap looked up by surface uv (bilinear, repeat wrap).
#pragma once
#include <memory>
#include <string>
#include <vector>
#include "core/math/vec.h"

namespace limn {

// Linear RGB image, rows stored top to bottom.
struct Bitmap {
  int width = 0, height = 0;
  std::vector<float> rgb;   // 3 * width * height
  std::string source;       // file it came from, for messages

  Spectrum texel(int x, int y) const {
    const size_t i = 3 * (size_t(y) * width + x);
    return Spectrum(rgb[i], rgb[i + 1], rgb[i + 2]);
  }
  // uv in [0,1)^2 with v = 0 at the bottom row (Blender's and Mitsuba's convention).
  Spectrum eval_bilinear(const Vec2& uv) const;
};

struct Texture {
  Spectrum value{0.5f};             // used when bitmap is null
  std::shared_ptr<Bitmap> bitmap;   // shared between textures that name the same file

  Spectrum eval(const Vec2& uv) const { return bitmap ? bitmap->eval_bilinear(uv) : value; }
  // Largest value the texture can return (for validation and Russian roulette bounds).
  Spectrum max_value() const;
};

}  // namespace limn
