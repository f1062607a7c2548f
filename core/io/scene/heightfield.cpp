#include "core/io/scene/shapes.h"

#include <cfloat>
#include "core/io/formats/files.h"
#include "core/io/formats/image_io.h"

namespace limn::io_detail {

// Heights from "filename" (an image: first channel, no sRGB decoding) or "data" (a 2D array, row 0 at
// the far edge y = +depth/2 as in an image), scaled by "height_scale".
ShapeGeometry load_heightfield(const Props& p, const std::string& type, const Transform& to_world) {
  Heightfield hf;
  if (p.has("filename") == p.has("data")) p.fail("needs exactly one of 'filename' (an image) or 'data' (a 2D array of heights)");
  const char* field = p.has("filename") ? "filename" : "data";
  if (p.has("filename")) {
    const std::string path = p.file("filename");
    Bitmap bm;
    try {
      bm = read_image(path, true);
    } catch (const std::invalid_argument& e) {
      p.fail(std::string("'filename': ") + e.what());
    }
    if (uint64_t(bm.width) * uint64_t(bm.height) > kMaxHeightfieldSamples)
      p.fail("'filename': " + std::to_string(bm.height) + " x " + std::to_string(bm.width) + " heights, more than the limit of " +
             std::to_string(kMaxHeightfieldSamples));
    hf.nx = bm.width;
    hf.ny = bm.height;
    hf.heights.resize(size_t(bm.width) * bm.height);
    for (size_t i = 0; i < hf.heights.size(); ++i) hf.heights[i] = bm.rgb[3 * i];
  } else {
    const ArrayData a = p.array("data");
    if (a.shape.size() != 2) p.fail("'data' must be a 2D array (rows, columns) of heights (got shape " + shape_text(a.shape) + ")");
    if (a.shape[0] > kMaxHeightfieldSamples || a.shape[1] > kMaxHeightfieldSamples || a.shape[0] * a.shape[1] > kMaxHeightfieldSamples)
      p.fail("'data' has " + std::to_string(a.shape[0]) + " x " + std::to_string(a.shape[1]) + " heights, more than the limit of " +
             std::to_string(kMaxHeightfieldSamples));
    hf.ny = int(a.shape[0]);
    hf.nx = int(a.shape[1]);
    hf.heights.assign(a.values.begin(), a.values.end());
  }
  if (hf.nx < 2 || hf.ny < 2)
    p.fail(std::string("'") + field + "': needs at least 2 x 2 heights (got " + std::to_string(hf.ny) + " rows x " + std::to_string(hf.nx) + " columns)");
  double lo = 0.0, hi = 0.0;
  for (size_t i = 0; i < hf.heights.size(); ++i) {
    if (!std::isfinite(hf.heights[i]))
      p.fail(std::string("'") + field + "': height at row " + std::to_string(i / hf.nx) + ", column " + std::to_string(i % hf.nx) + " is not finite (" +
             number_text(hf.heights[i]) + ")");
    lo = std::min(lo, double(hf.heights[i]));
    hi = std::max(hi, double(hf.heights[i]));
  }
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
  const double scale = check_similarity(p, to_world);
  hf.scale = float(scale);
  hf.world_from_local = to_world;

  // What the float arithmetic of the surface and its traversal meets: the extents in the local
  // frame and in the world, and the corners of its box in the world, must be normal floats.
  const double extents[3] = {double(hf.width), double(hf.depth), std::max(hi - lo, std::max(std::abs(lo), std::abs(hi))) * hf.height_scale};
  const char* names[3] = {"width (size[0])", "depth (size[1])", "height range (heights x height_scale)"};
  for (int k = 0; k < 3; ++k) {
    const double world = extents[k] * scale;
    if (!(extents[k] <= double(kMaxRadius)) || !(extents[k] == 0.0 || extents[k] >= double(kMinRadius)) || !(world <= double(kMaxRadius)) ||
        !(extents[k] == 0.0 || world >= double(kMinRadius)))
      p.fail(std::string("the ") + names[k] + " is " + number_text(extents[k]) + ", " + number_text(world) +
             " after 'to_world' (scale " + number_text(scale) + "); both must be within [" + number_text(kMinRadius) + ", " + number_text(kMaxRadius) + "]");
  }
  if (!std::isnormal(hf.scale))
    p.fail("'to_world' scales by " + number_text(scale) + ", which is not a normal float");
  for (int c = 0; c < 8; ++c) {
    const Vec3d local((c & 1 ? 0.5 : -0.5) * hf.width, (c & 2 ? 0.5 : -0.5) * hf.depth, (c & 4 ? hi : lo) * hf.height_scale);
    const Vec3d w = Vec3d(to_world.matrix() * glm::dvec4(local, 1.0));
    for (int a = 0; a < 3; ++a)
      if (!(std::abs(w[a]) <= kMaxCoordinate))
        p.fail("'to_world' moves the corner [" + number_text(local.x) + ", " + number_text(local.y) + ", " + number_text(local.z) + "] to [" +
               number_text(w.x) + ", " + number_text(w.y) + ", " + number_text(w.z) + "], beyond " + number_text(kMaxCoordinate) +
               ", the largest world coordinate limn traces rays at");
  }
  return hf;
}

}  // namespace limn::io_detail
