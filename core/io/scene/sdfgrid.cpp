#include <cstring>
#include <fstream>
#include "core/io/scene/shapes.h"

namespace limn::io_detail {
namespace {

// Mitsuba's grid volume file (.vol), the format its sdfgrid reads: "VOL", version byte 3, then
// little-endian int32 encoding (1 = float32), int32 xres, yres, zres, int32 channels, six float32
// bounds (ignored: the grid spans the unit cube, placed by to_world), and xres * yres * zres *
// channels float32 values, x fastest, then y, then z ([z][y][x], as the "data" array).
void read_vol(const Props& p, const std::string& path, SdfGrid& g) {
  std::ifstream in(path, std::ios::binary);
  if (!in) p.fail("cannot open '" + path + "'");
  char magic[4];
  int32_t header[5];
  float bounds[6];
  if (!in.read(magic, 4) || !in.read(reinterpret_cast<char*>(header), sizeof(header)) || !in.read(reinterpret_cast<char*>(bounds), sizeof(bounds)))
    p.fail("'" + path + "' is too short for a .vol header (48 bytes)");
  if (std::memcmp(magic, "VOL", 3) != 0 || magic[3] != 3)
    p.fail("'" + path + "' is not a version-3 .vol file (Mitsuba's grid volume: it starts with \"VOL\" and the byte 3)");
  if (header[0] != 1) p.fail("'" + path + "': encoding " + std::to_string(header[0]) + " is not supported (only 1, float32)");
  if (header[4] != 1) p.fail("'" + path + "': has " + std::to_string(header[4]) + " channels (a signed distance grid has 1)");
  for (int a = 0; a < 3; ++a)
    if (header[1 + a] < 2 || header[1 + a] > 4096)
      p.fail("'" + path + "': resolution " + std::to_string(header[1]) + " x " + std::to_string(header[2]) + " x " + std::to_string(header[3]) +
             " (x, y, z) is out of range (2 to 4096 samples per axis)");
  g.nx = header[1];
  g.ny = header[2];
  g.nz = header[3];
  g.values.resize(size_t(g.nx) * g.ny * g.nz);
  if (!in.read(reinterpret_cast<char*>(g.values.data()), std::streamsize(g.values.size() * sizeof(float))))
    p.fail("'" + path + "' ends before its " + std::to_string(g.values.size()) + " values");
}

}  // namespace

// A grid of signed distances from "data" (a 3D array indexed [z, y, x]) or "filename" (a .vol file).
ShapeGeometry load_sdfgrid(const Props& p, const std::string&, const Transform& to_world) {
  SdfGrid g;
  if (p.has("filename") == p.has("data")) p.fail("needs exactly one of 'filename' (a .vol file) or 'data' (a 3D array indexed [z, y, x])");
  if (p.has("filename")) {
    read_vol(p, p.file("filename"), g);
  } else {
    const ArrayData a = p.array("data");
    if (a.shape.size() != 3) p.fail("'data' must be a 3D array indexed [z, y, x] (got " + std::to_string(a.shape.size()) + " dimensions)");
    if (a.shape[0] > 4096 || a.shape[1] > 4096 || a.shape[2] > 4096) p.fail("'data' has more than 4096 samples along an axis");
    g.nz = int(a.shape[0]);
    g.ny = int(a.shape[1]);
    g.nx = int(a.shape[2]);
    g.values.assign(a.values.begin(), a.values.end());
  }
  if (g.nx < 2 || g.ny < 2 || g.nz < 2)
    p.fail("needs at least 2 x 2 x 2 samples (got [z, y, x] = [" + std::to_string(g.nz) + ", " + std::to_string(g.ny) + ", " + std::to_string(g.nx) + "])");
  for (size_t i = 0; i < g.values.size(); ++i)
    if (!std::isfinite(g.values[i]))
      p.fail("value at [z, y, x] = [" + std::to_string(i / (size_t(g.nx) * g.ny)) + ", " + std::to_string((i / size_t(g.nx)) % size_t(g.ny)) + ", " +
             std::to_string(i % size_t(g.nx)) + "] is not finite (" + std::to_string(g.values[i]) + ")");
  const Mat4d& m = to_world.matrix();
  if (!(std::abs(glm::determinant(glm::dmat3(m))) > 0.0)) p.fail("to_world must be invertible");
  g.world_from_local = to_world;
  return g;
}

}  // namespace limn::io_detail
