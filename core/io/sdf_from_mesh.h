// A signed-distance grid from a closed triangle mesh (issue 37): the input of an `sdfgrid` shape
// (in io: it prepares input and uses render's Embree device and RenderCancelled).
//
// Distance: the closest point on the triangles, found with Embree point queries (rtcPointQuery over
// a BVH of the triangles, the query radius shrinking to the best distance so far). Sign: ray parity,
// the number of surface crossings along a ray from the sample to infinity, taken along three fixed
// generic directions and decided by majority (one ray that grazes an edge or vertex and counts a
// crossing twice or not at all is outvoted). Parity needs a closed surface, so the mesh must be
// closed: every edge is shared by exactly two triangles, in opposite directions (consistently
// oriented); anything else is refused with the count and one offending edge.
//
// The grid: cubic voxels; `resolution` samples along the bounding box's longest side (grown by
// `padding` times that side on every side), the other axes as many samples as the same voxel size
// needs to cover them (at least 2). Corner samples as in `sdfgrid`: sample [z][y][x] sits at
// origin + voxel * (x, y, z), and to_world maps the unit cube onto [origin, origin + voxel * (n - 1)].
// Values are signed distances in the mesh's units, negative inside.
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace limn {

struct SdfFromMesh {
  int nx = 0, ny = 0, nz = 0;
  std::vector<float> values;                  // [z][y][x], x fastest
  std::array<double, 3> origin{}, extent{};   // world box of the grid: to_world = translate(origin) * scale(extent)
  double voxel = 0.0;                          // sample spacing (extent = voxel * (n - 1) per axis)
  size_t sign_disagreements = 0;               // samples whose three parity rays did not agree (majority taken)
};

// Limits on `resolution` (samples along the longest side).
inline constexpr int kSdfFromMeshMinResolution = 2;
inline constexpr int kSdfFromMeshMaxResolution = 1024;
// Largest grid (samples) accepted: 2^28 floats are 1 GiB.
inline constexpr size_t kSdfFromMeshMaxSamples = size_t(1) << 28;

// vertices: 3 doubles per vertex; faces: 3 indices per triangle. `what` names the mesh in errors.
// `progress(fraction)` returning false cancels (throws RenderCancelled). Throws std::invalid_argument
// for bad input: no triangles, non-finite vertices, indices out of range, a mesh that is not closed
// and consistently oriented, a zero-volume bounding box, resolution outside [2, 1024], padding
// negative or not finite, a grid beyond kSdfFromMeshMaxSamples.
SdfFromMesh sdf_from_mesh(const std::vector<double>& vertices, const std::vector<int64_t>& faces, int resolution,
                          double padding, const std::string& what = "mesh",
                          const std::function<bool(float)>& progress = {});

// Distance from p to the triangle (a, b, c) and the closest point (exposed for the tests).
double point_triangle_distance(const std::array<double, 3>& p, const std::array<double, 3>& a,
                               const std::array<double, 3>& b, const std::array<double, 3>& c,
                               std::array<double, 3>* closest = nullptr);

}  // namespace limn
