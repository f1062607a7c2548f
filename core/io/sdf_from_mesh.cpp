#include "core/io/sdf_from_mesh.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include "core/render/accel.h"
#include "core/render/integrators/render.h"

namespace limn {

namespace {

using V3 = std::array<double, 3>;

V3 sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
V3 lerp(const V3& a, const V3& b, double t) { return {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])}; }
double dist2(const V3& a, const V3& b) {
  const V3 d = sub(a, b);
  return dot(d, d);
}

// Closest point of the segment [a, b] to p.
V3 closest_on_segment(const V3& p, const V3& a, const V3& b) {
  const V3 ab = sub(b, a);
  const double len2 = dot(ab, ab);
  if (len2 <= 0.0) return a;
  return lerp(a, b, std::clamp(dot(sub(p, a), ab) / len2, 0.0, 1.0));
}

struct Triangles {
  const std::vector<double>* vertices;
  const std::vector<int64_t>* faces;
  V3 vertex(int64_t i) const { return {(*vertices)[3 * i], (*vertices)[3 * i + 1], (*vertices)[3 * i + 2]}; }
  V3 corner(size_t face, int k) const { return vertex((*faces)[3 * face + k]); }
};

struct QueryState {
  const Triangles* tris;
  V3 p;
  double best2 = std::numeric_limits<double>::infinity();
};

// Embree point-query callback: the distance to one triangle; shrinks the query sphere when closer.
bool closest_triangle(RTCPointQueryFunctionArguments* args) {
  auto* st = static_cast<QueryState*>(args->userPtr);
  const size_t f = args->primID;
  const double d2 = [&] {
    const double d = point_triangle_distance(st->p, st->tris->corner(f, 0), st->tris->corner(f, 1), st->tris->corner(f, 2));
    return d * d;
  }();
  if (d2 < st->best2) {
    st->best2 = d2;
    // Rounded up: a float radius below the best distance could cull a triangle that is closer.
    args->query->radius = std::nextafter(float(std::sqrt(d2)), std::numeric_limits<float>::infinity());
    return true;
  }
  return false;
}

// Three fixed unit directions, none along an axis or a diagonal (grid-aligned meshes would put
// such rays exactly through their edges).
constexpr double kParityDirs[3][3] = {{0.5377, 0.2718, 0.7982}, {-0.6131, 0.7154, 0.3352}, {0.2391, -0.8847, 0.4002}};

}  // namespace

double point_triangle_distance(const V3& p, const V3& a, const V3& b, const V3& c, V3* closest) {
  // Inside the prism over the triangle: the foot of the perpendicular; otherwise the closest point
  // lies on the boundary, the nearest of the three edges' closest points.
  const V3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  const V3 n = cross(ab, ac);
  const double n2 = dot(n, n);
  V3 best{};
  double best2 = std::numeric_limits<double>::infinity();
  if (n2 > 0.0) {
    // Barycentric coordinates of p's projection: (v, w) for b and c.
    const double v = dot(cross(ap, ac), n) / n2, w = dot(cross(ab, ap), n) / n2;
    if (v >= 0.0 && w >= 0.0 && v + w <= 1.0) {
      best = {a[0] + v * ab[0] + w * ac[0], a[1] + v * ab[1] + w * ac[1], a[2] + v * ab[2] + w * ac[2]};
      best2 = dist2(p, best);
    }
  }
  if (!(best2 < std::numeric_limits<double>::infinity())) {
    for (const auto& [s, e] : {std::pair{&a, &b}, std::pair{&b, &c}, std::pair{&c, &a}}) {
      const V3 q = closest_on_segment(p, *s, *e);
      const double d2 = dist2(p, q);
      if (d2 < best2) best2 = d2, best = q;
    }
  }
  if (closest) *closest = best;
  return std::sqrt(best2);
}

SdfFromMesh sdf_from_mesh(const std::vector<double>& vertices, const std::vector<int64_t>& faces, int resolution,
                          double padding, const std::string& what, const std::function<bool(float)>& progress) {
  auto fail = [&](const std::string& why) { throw std::invalid_argument("sdf_from_mesh: " + what + ": " + why); };
  if (vertices.size() % 3 != 0) fail("vertex array length " + std::to_string(vertices.size()) + " is not a multiple of 3");
  if (faces.size() % 3 != 0) fail("face array length " + std::to_string(faces.size()) + " is not a multiple of 3");
  const size_t nv = vertices.size() / 3, nf = faces.size() / 3;
  if (nf == 0) fail("the mesh has no triangles (" + std::to_string(nv) + " vertices); a signed distance needs a closed surface");
  if (resolution < kSdfFromMeshMinResolution || resolution > kSdfFromMeshMaxResolution)
    fail("resolution must be within [" + std::to_string(kSdfFromMeshMinResolution) + ", " +
         std::to_string(kSdfFromMeshMaxResolution) + "] samples along the longest side (got " + std::to_string(resolution) + ")");
  if (!std::isfinite(padding) || padding < 0.0 || padding > 10.0)
    fail("padding must be a finite share of the longest side within [0, 10] (got " + std::to_string(padding) + ")");
  for (size_t i = 0; i < vertices.size(); ++i)
    if (!std::isfinite(vertices[i]))
      fail("vertex " + std::to_string(i / 3) + " has a non-finite coordinate (" + std::to_string(vertices[i]) + ")");
  for (size_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      const int64_t i = faces[3 * f + k];
      if (i < 0 || size_t(i) >= nv)
        fail("triangle " + std::to_string(f) + " refers to vertex " + std::to_string(i) + ", outside [0, " + std::to_string(nv) + ")");
    }
    const int64_t a = faces[3 * f], b = faces[3 * f + 1], c = faces[3 * f + 2];
    if (a == b || b == c || c == a)
      fail("triangle " + std::to_string(f) + " repeats a vertex (" + std::to_string(a) + ", " + std::to_string(b) + ", " +
           std::to_string(c) + ")");
  }
  // Closed and consistently oriented: each directed edge once, and its reverse once.
  {
    std::unordered_map<uint64_t, uint32_t> directed;
    directed.reserve(3 * nf);
    auto key = [nv](int64_t a, int64_t b) { return uint64_t(a) * uint64_t(nv) + uint64_t(b); };
    for (size_t f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) ++directed[key(faces[3 * f + k], faces[3 * f + (k + 1) % 3])];
    size_t open = 0, nonmanifold = 0;
    std::string example;
    for (const auto& [k, count] : directed) {
      const int64_t a = int64_t(k / nv), b = int64_t(k % nv);
      const auto rev = directed.find(key(b, a));
      const uint32_t back = rev == directed.end() ? 0 : rev->second;
      if (count == 1 && back == 1) continue;
      (count > 1 || back > 1 ? nonmanifold : open) += 1;
      if (example.empty())
        example = "edge (" + std::to_string(a) + ", " + std::to_string(b) + ") is used " + std::to_string(count) +
                  " time(s) in that direction and " + std::to_string(back) + " time(s) reversed";
    }
    if (open + nonmanifold > 0)
      fail("the mesh is not closed and consistently oriented (" + std::to_string(open) + " open or flipped and " +
           std::to_string(nonmanifold) + " non-manifold directed edges; e.g. " + example +
           "); the inside of a signed distance needs a watertight surface: fill the holes, merge duplicate vertices and "
           "recalculate the normals");
  }

  V3 lo{vertices[0], vertices[1], vertices[2]}, hi = lo;
  for (size_t i = 0; i < nv; ++i)
    for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], vertices[3 * i + k]), hi[k] = std::max(hi[k], vertices[3 * i + k]);
  const double longest = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  if (!(longest > 0.0) || !std::isfinite(longest)) fail("the mesh's bounding box has no extent");

  SdfFromMesh out;
  const double pad = padding * longest;
  out.voxel = (longest + 2.0 * pad) / double(resolution - 1);
  int n[3];
  for (int k = 0; k < 3; ++k) {
    // Enough samples to cover the padded side; the grid is centred on the bounding box.
    const double side = hi[k] - lo[k] + 2.0 * pad;
    n[k] = std::max(2, int(std::ceil(side / out.voxel - 1e-9)) + 1);  // 1e-9: the longest side is an exact multiple
    out.extent[k] = out.voxel * double(n[k] - 1);
    out.origin[k] = 0.5 * (lo[k] + hi[k]) - 0.5 * out.extent[k];
  }
  out.nx = n[0], out.ny = n[1], out.nz = n[2];
  const size_t total = size_t(n[0]) * size_t(n[1]) * size_t(n[2]);
  if (total > kSdfFromMeshMaxSamples)
    fail("a grid of " + std::to_string(n[0]) + " x " + std::to_string(n[1]) + " x " + std::to_string(n[2]) +
         " samples is too large (at most " + std::to_string(kSdfFromMeshMaxSamples) + "); lower the resolution");
  out.values.resize(total);

  // Embree scene of the triangles (float copies; distances are computed in double from the input).
  RTCDevice device = EmbreeDevice::get();
  RTCScene scene = rtcNewScene(device);
  rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);  // watertight traversal: no ray slips between two triangles
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), nv));
  auto* ib = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), nf));
  struct Release {
    RTCScene s;
    ~Release() { rtcReleaseScene(s); }
  } release{scene};
  if (!vb || !ib) {
    rtcReleaseGeometry(geom);
    EmbreeDevice::check("sdf_from_mesh: " + what);
    fail("Embree could not allocate the buffers");
  }
  for (size_t i = 0; i < 3 * nv; ++i) vb[i] = float(vertices[i]);
  for (size_t i = 0; i < 3 * nf; ++i) ib[i] = uint32_t(faces[i]);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(scene);
  EmbreeDevice::check("sdf_from_mesh: " + what);

  const Triangles tris{&vertices, &faces};
  const double scale = std::sqrt(dist2(lo, hi));
  std::atomic<size_t> disagreements{0};
  // Crossings along the ray p + t d, t > 0: the next search starts just past each hit (1e-7 of the
  // mesh's diagonal, far above float rounding of the hit distance, far below any feature a
  // resolution <= 1024 grid resolves).
  auto crossings = [&](const V3& p, const double* d) {
    int count = 0;
    float tnear = 0.0f;
    for (int guard = 0; guard < 1 << 16; ++guard) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      RTCRayHit rh{};
      rh.ray.org_x = float(p[0]), rh.ray.org_y = float(p[1]), rh.ray.org_z = float(p[2]);
      rh.ray.dir_x = float(d[0]), rh.ray.dir_y = float(d[1]), rh.ray.dir_z = float(d[2]);
      rh.ray.tnear = tnear;
      rh.ray.tfar = std::numeric_limits<float>::infinity();
      rh.ray.mask = 0xFFFFFFFFu;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene, &ctx, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) break;
      ++count;
      tnear = rh.ray.tfar + float(1e-7 * scale);
    }
    return count;
  };

  const int nx = n[0], ny = n[1], nz = n[2];
  for (int z = 0; z < nz; ++z) {
    tbb::parallel_for(tbb::blocked_range<int>(0, ny), [&](const tbb::blocked_range<int>& r) {
      for (int y = r.begin(); y < r.end(); ++y)
        for (int x = 0; x < nx; ++x) {
          const V3 p{out.origin[0] + out.voxel * x, out.origin[1] + out.voxel * y, out.origin[2] + out.voxel * z};
          QueryState st{&tris, p};
          RTCPointQuery q;
          q.x = float(p[0]), q.y = float(p[1]), q.z = float(p[2]);
          q.time = 0.0f;
          q.radius = std::numeric_limits<float>::infinity();
          RTCPointQueryContext qc;
          rtcInitPointQueryContext(&qc);
          rtcPointQuery(scene, &q, &qc, closest_triangle, &st);
          int odd = 0;
          for (const auto& d : kParityDirs) odd += crossings(p, d) & 1;
          if (odd == 1 || odd == 2) disagreements.fetch_add(1, std::memory_order_relaxed);
          const double dist = std::sqrt(st.best2);
          out.values[(size_t(z) * ny + y) * nx + x] = float(odd >= 2 ? -dist : dist);
        }
    });
    if (progress && !progress(float(z + 1) / float(nz))) throw RenderCancelled();
  }
  EmbreeDevice::check("sdf_from_mesh: " + what);
  out.sign_disagreements = disagreements.load();
  for (float v : out.values)
    if (!std::isfinite(v)) fail("internal error: a sample's distance is not finite (Embree found no triangle)");
  return out;
}

}  // namespace limn
