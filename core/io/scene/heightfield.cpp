#include "core/io/scene/shapes.h"

#include "core/io/formats/image_io.h"

namespace limn::io_detail {

// Heights from "filename" (any OpenImageIO format, first channel, no sRGB decoding) or "data" (a 2D
// array, row 0 at the far edge y = +depth/2 as in an image), scaled by "height_scale".
ShapeGeometry load_heightfield(const Props& p, const std::string& type, const Transform& to_world) {
  Heightfield hf;
  if (p.has("filename") == p.has("data")) p.fail("needs exactly one of 'filename' (an image) or 'data' (a 2D array of heights)");
  if (p.has("filename")) {
    const std::string path = p.file("filename");
    Bitmap bm;
    try {
      bm = read_image(path, true);
    } catch (const std::invalid_argument& e) {
      p.fail(e.what());
    }
    hf.nx = bm.width;
    hf.ny = bm.height;
    hf.heights.resize(size_t(bm.width) * bm.height);
    for (size_t i = 0; i < hf.heights.size(); ++i) hf.heights[i] = bm.rgb[3 * i];
  } else {
    const ArrayData a = p.array("data");
    if (a.shape.size() != 2) p.fail("'data' must be a 2D array (rows, columns) of heights");
    hf.ny = int(a.shape[0]);
    hf.nx = int(a.shape[1]);
    hf.heights.assign(a.values.begin(), a.values.end());
  }
  if (hf.nx < 2 || hf.ny < 2)
    p.fail("needs at least 2 x 2 heights (got " + std::to_string(hf.ny) + " rows x " + std::to_string(hf.nx) + " columns)");
  for (size_t i = 0; i < hf.heights.size(); ++i)
    if (!std::isfinite(hf.heights[i]))
      p.fail("height at row " + std::to_string(i / hf.nx) + ", column " + std::to_string(i % hf.nx) + " is not finite");
  Vec2 size(2.0f);
  if (p.has("size")) {
    const std::vector<double> v = p.numbers(p.raw("size"), "size", 2);
    size = Vec2(float(v[0]), float(v[1]));
  }
  hf.width = size.x;
  hf.depth = size.y;
  if (!(hf.width > 0.0f && hf.depth > 0.0f && std::isfinite(hf.width) && std::isfinite(hf.depth)))
    p.fail("size must be two positive numbers [width, depth] (got [" + std::to_string(hf.width) + ", " + std::to_string(hf.depth) + "])");
  hf.height_scale = p.number("height_scale", 1.0f);
  if (!(hf.height_scale > 0.0f && std::isfinite(hf.height_scale)))
    p.fail("height_scale must be finite and > 0 (got " + std::to_string(hf.height_scale) + ")");
  check_similarity(p, to_world, hf.scale);
  hf.world_from_local = to_world;
  return hf;
}

}  // namespace limn::io_detail
