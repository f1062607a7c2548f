#include "core/render/textures/texture.h"

namespace limn {

Spectrum Bitmap::eval_bilinear(const Vec2& uv) const {
  // Texel centres sit at half-integer coordinates; repeat wrap in both directions.
  const float x = uv.x * width - 0.5f;
  const float y = (1.0f - uv.y) * height - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const float tx = x - fx, ty = y - fy;
  auto wrap = [](int i, int n) { const int m = i % n; return m < 0 ? m + n : m; };
  const int x0 = wrap(int(fx), width), x1 = wrap(int(fx) + 1, width);
  const int y0 = wrap(int(fy), height), y1 = wrap(int(fy) + 1, height);
  return (1 - ty) * ((1 - tx) * texel(x0, y0) + tx * texel(x1, y0)) + ty * ((1 - tx) * texel(x0, y1) + tx * texel(x1, y1));
}

Spectrum Texture::max_value() const {
  if (!bitmap) return value;
  Spectrum m(0.0f);
  for (size_t i = 0; i < bitmap->rgb.size(); i += 3)
    m = glm::max(m, Spectrum(bitmap->rgb[i], bitmap->rgb[i + 1], bitmap->rgb[i + 2]));
  return m;
}

}  // namespace limn
