#include "core/geometry/shapes/mesh.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <map>
#include <stdexcept>
#include <unordered_map>
#include "core/math/warp.h"

namespace limn {

void Mesh::update_derived() {
  const size_t nt = triangle_count();
  if (vertex_face_offsets.size() != vertex_count() + 1) {  // topology is fixed: build once
    vertex_face_offsets.assign(vertex_count() + 1, 0);
    for (uint32_t i : indices) vertex_face_offsets[i + 1]++;
    for (size_t v = 0; v < vertex_count(); ++v) vertex_face_offsets[v + 1] += vertex_face_offsets[v];
    vertex_faces.assign(indices.size(), 0);
    std::vector<uint32_t> fill(vertex_face_offsets.begin(), vertex_face_offsets.end() - 1);
    for (size_t f = 0; f < nt; ++f)
      for (int k = 0; k < 3; ++k) vertex_faces[fill[indices[3 * f + k]]++] = uint32_t(f);
    // Duplicated triangles (the same corners in either winding): the first one stands for all.
    distinct.resize(nt);
    std::map<std::array<uint32_t, 3>, int> first;
    for (size_t f = 0; f < nt; ++f) {
      std::array<uint32_t, 3> corners{indices[3 * f], indices[3 * f + 1], indices[3 * f + 2]};
      std::sort(corners.begin(), corners.end());
      distinct[f] = first.try_emplace(corners, int(f)).first->second;
    }
    // Undirected edges: two triangles around a vertex share an edge when they share another vertex.
    std::unordered_map<uint64_t, size_t> slot;
    std::unordered_map<size_t, std::vector<int>> more_of;  // non-manifold edges' later triangles, by edge
    edges.clear();
    edge_more_faces.clear();
    for (size_t f = 0; f < nt; ++f)
      for (int k = 0; k < 3 && distinct[f] == int(f); ++k) {
        uint32_t a = indices[3 * f + k], b = indices[3 * f + (k + 1) % 3];
        if (a > b) std::swap(a, b);
        if (a == b) continue;
        auto [it, inserted] = slot.try_emplace((uint64_t(a) << 32) | b, edges.size());
        if (inserted) {
          edges.push_back({a, b, int(f), -1, 1});
          continue;
        }
        MeshEdge& e = edges[it->second];
        if (e.face_count == 1) e.face1 = int(f);
        else more_of[it->second].push_back(int(f));
        e.face_count++;
      }
    for (size_t i = 0; i < edges.size(); ++i) {
      if (edges[i].face_count <= 2) continue;
      edges[i].more = uint32_t(edge_more_faces.size());
      const std::vector<int>& faces = more_of[i];
      edge_more_faces.insert(edge_more_faces.end(), faces.begin(), faces.end());
    }
    orient();
  }
  triangle_areas.assign(nt, 0.0f);
  vertex_normals.assign(face_normals ? 0 : vertex_count(), Vec3(0.0f));
  double total = 0.0;
  for (size_t f = 0; f < nt; ++f) {
    const uint32_t i0 = indices[3 * f], i1 = indices[3 * f + 1], i2 = indices[3 * f + 2];
    const Vec3 c = glm::cross(vertex(i1) - vertex(i0), vertex(i2) - vertex(i0));
    const float area = 0.5f * glm::length(c);
    triangle_areas[f] = std::isfinite(area) ? area : 0.0f;
    total += triangle_areas[f];
    // Area-weighted normals: the unnormalised cross product is 2 * area * n.
    if (!face_normals && std::isfinite(area) && normal_sign(f) != 0)
      for (uint32_t i : {i0, i1, i2}) vertex_normals[i] += float(normal_sign(f)) * c;
  }
  for (auto& n : vertex_normals) {
    const float len = glm::length(n);
    n = len > 0.0f ? n / len : Vec3(0.0f);
  }
  total_area = float(total);
  area_distribution = nt > 0 ? Distribution1D(triangle_areas) : Distribution1D();
}

namespace {

// +1 when triangle f runs along its edge from a to b, -1 when from b to a, 0 when it has no such edge.
int edge_direction(const std::vector<uint32_t>& indices, int f, uint32_t a, uint32_t b) {
  for (int k = 0; k < 3; ++k) {
    const uint32_t p = indices[3 * size_t(f) + k], q = indices[3 * size_t(f) + (k + 1) % 3];
    if (p == a && q == b) return 1;
    if (p == b && q == a) return -1;
  }
  return 0;
}

}  // namespace

void Mesh::orient() {
  const size_t nt = triangle_count();
  orientation.assign(nt, 0);
  std::vector<std::vector<std::pair<int, size_t>>> across(nt);  // triangles across two-triangle edges: (neighbour, edge)
  for (size_t i = 0; i < edges.size(); ++i) {
    const MeshEdge& e = edges[i];
    if (e.face_count != 2) continue;
    across[size_t(e.face0)].push_back({e.face1, i});
    across[size_t(e.face1)].push_back({e.face0, i});
  }
  // Breadth-first over each connected part: a neighbour that runs along the shared edge the same
  // way as its triangle is flipped relative to it.
  std::vector<int> queue;
  for (size_t seed = 0; seed < nt; ++seed) {
    if (orientation[seed] != 0 || distinct[seed] != int(seed)) continue;
    queue.assign(1, int(seed));
    orientation[seed] = 1;
    double volume = 0.0, area = 0.0;
    bool closed = true;
    for (size_t head = 0; head < queue.size(); ++head) {
      const int f = queue[head];
      const uint32_t* i = &indices[3 * size_t(f)];
      const Vec3d p0(vertex(i[0])), p1(vertex(i[1])), p2(vertex(i[2]));
      const Vec3d c = glm::cross(p1 - p0, p2 - p0);
      if (std::isfinite(c.x + c.y + c.z)) {
        volume += orientation[size_t(f)] * glm::dot(p0, c) / 6.0;  // divergence theorem, one tetrahedron per triangle
        area += orientation[size_t(f)] * 0.5 * glm::length(c);
      }
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = i[k], b = i[(k + 1) % 3];
        bool manifold = false;
        for (const auto& [g, ei] : across[size_t(f)]) {
          const MeshEdge& e = edges[ei];
          if (!((e.a == a && e.b == b) || (e.a == b && e.b == a))) continue;
          manifold = true;
          const int8_t want = int8_t(edge_direction(indices, f, a, b) == edge_direction(indices, g, a, b) ? -orientation[size_t(f)]
                                                                                                           : orientation[size_t(f)]);
          if (orientation[size_t(g)] == 0) {
            orientation[size_t(g)] = want;
            queue.push_back(g);
          }
        }
        if (a != b && !manifold) closed = false;
      }
    }
    if (closed ? volume < 0.0 : area < 0.0)
      for (int f : queue) orientation[size_t(f)] = int8_t(-orientation[size_t(f)]);
  }
  for (size_t f = 0; f < nt; ++f) {
    const int twin = distinct[f];
    if (twin != int(f)) {  // a duplicate: the twin's orientation, turned if wound the other way
      const uint32_t a = indices[3 * f], b = indices[3 * f + 1];
      orientation[f] = int8_t(edge_direction(indices, int(f), a, b) == edge_direction(indices, twin, a, b) ? orientation[size_t(twin)]
                                                                                                          : -orientation[size_t(twin)]);
    }
  }
}

void Mesh::fill_interaction(int prim, float b1, float b2, SurfaceInteraction& si) const {
  const uint32_t i0 = indices[3 * prim], i1 = indices[3 * prim + 1], i2 = indices[3 * prim + 2];
  const Vec3 p0 = vertex(i0), p1 = vertex(i1), p2 = vertex(i2);
  const float b0 = 1.0f - b1 - b2;
  si.p = b0 * p0 + b1 * p1 + b2 * p2;
  // Error of the barycentric sum (pbrt-v4, section 6.8.6): gamma(7) * sum |b_i p_i|.
  si.p_error = gamma_bound(7) * (glm::abs(b0 * p0) + glm::abs(b1 * p1) + glm::abs(b2 * p2));
  const Vec3 c = glm::cross(p1 - p0, p2 - p0);
  const float len = glm::length(c);
  si.ng = len > 0.0f ? c / len : Vec3(0, 0, 1);
  si.ns = si.ng;
  if (!face_normals) {
    const Vec3 n = b0 * vertex_normals[i0] + b1 * vertex_normals[i1] + b2 * vertex_normals[i2];
    const float ln = glm::length(n);
    if (ln > 0.0f) si.ns = glm::dot(n, si.ng) >= 0.0f ? n / ln : -n / ln;
  }
  if (!corner_uvs.empty()) {
    const float* t = &corner_uvs[6 * size_t(prim)];
    si.uv = b0 * Vec2(t[0], t[1]) + b1 * Vec2(t[2], t[3]) + b2 * Vec2(t[4], t[5]);
  } else {
    si.uv = Vec2(b1, b2);
  }
  si.bary = Vec2(b1, b2);
  si.prim = prim;
  si.frame = Frame(si.ns);
}

PositionSample Mesh::sample_position(const Vec2& u, float u_tri) const {
  float pdf_tri = 0.0f;
  size_t prim = 0;
  area_distribution.sample_continuous(u_tri, &prim, &pdf_tri);
  const Vec2 b = warp::square_to_uniform_triangle(u);
  SurfaceInteraction si;
  fill_interaction(int(prim), b.x, b.y, si);
  // P(triangle) = area_f / total, then uniform on it: pdf_area = 1 / total_area.
  return PositionSample{si.p, si.ng, si.uv, total_area > 0.0f ? 1.0f / total_area : 0.0f, int(prim), b};
}

RTCGeometry Mesh::create_embree_geometry(RTCDevice device) const {
  RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  // Embree-owned buffers (padded as Embree requires); our copy stays the one users edit.
  rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), vertex_count());
  auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                             3 * sizeof(uint32_t), triangle_count()));
  std::memcpy(idx, indices.data(), indices.size() * sizeof(uint32_t));
  update_embree_geometry(g);
  // Vertices move during optimisation: refit the BVH instead of rebuilding it.
  rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_REFIT);
  return g;
}

void Mesh::update_embree_geometry(RTCGeometry g) const {
  auto* dst = static_cast<float*>(rtcGetGeometryBufferData(g, RTC_BUFFER_TYPE_VERTEX, 0));
  std::memcpy(dst, positions.data(), positions.size() * sizeof(float));
  rtcUpdateGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0);
}

void Mesh::list_parameters(const std::string& id, int index, std::vector<Parameter>& out) {
  out.push_back({id + ".vertex_positions", Parameter::Kind::VertexPositions, index, positions.data(), {vertex_count(), 3}, true});
}

void Mesh::validate_parameter(const Parameter& p, const std::string& where) const {
  for (size_t i = 0; i < p.size(); i += 3) {
    if (!std::isfinite(p.data[i]) || !std::isfinite(p.data[i + 1]) || !std::isfinite(p.data[i + 2]))
      throw std::invalid_argument(where + ": vertex " + std::to_string(i / 3) + " is not finite (" + format_values(p.data + i, 3) + ")");
    if (max_component(glm::abs(Vec3(p.data[i], p.data[i + 1], p.data[i + 2]))) > kMaxCoordinate)
      throw std::invalid_argument(where + ": vertex " + std::to_string(i / 3) + " (" + format_values(p.data + i, 3) +
                                  ") is beyond the traceable range (|coordinate| <= 1e18)");
  }
  // As loading refuses them: p.data are this mesh's positions, edited in place.
  for (size_t f = 0; f < triangle_count(); ++f)
    if (degenerate(f))
      throw std::invalid_argument(where + ": triangle " + std::to_string(f) + " is degenerate (vertices " +
                                  std::to_string(indices[3 * f]) + ", " + std::to_string(indices[3 * f + 1]) + ", " +
                                  std::to_string(indices[3 * f + 2]) + " enclose zero area)");
}

void Mesh::translate(const Vec3& delta) {
  for (size_t k = 0; k < positions.size(); ++k) positions[k] += delta[int(k % 3)];
}

void Mesh::bounds(Vec3& lo, Vec3& hi) const {
  lo = Vec3(kInfinity);
  hi = Vec3(-kInfinity);
  for (size_t v = 0; v < vertex_count(); ++v) {
    lo = glm::min(lo, vertex(uint32_t(v)));
    hi = glm::max(hi, vertex(uint32_t(v)));
  }
}

void Mesh::geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const {
  values.insert(values.end(), positions.begin(), positions.end());
  Vec3 l, h;
  bounds(l, h);
  lo = glm::min(lo, l);
  hi = glm::max(hi, h);
}

std::vector<uint32_t> weld_by_position(const std::vector<float>& positions, const std::vector<uint32_t>& indices,
                                       std::vector<float>& welded) {
  struct Key {
    uint32_t x, y, z;
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    size_t operator()(const Key& k) const { return (size_t(k.x) * 73856093u) ^ (size_t(k.y) * 19349663u) ^ (size_t(k.z) * 83492791u); }
  };
  auto bits = [](float f) {
    if (f == 0.0f) f = 0.0f;  // -0 and +0 are the same position
    uint32_t u;
    std::memcpy(&u, &f, 4);
    return u;
  };
  std::unordered_map<Key, uint32_t, KeyHash> map;
  map.reserve(positions.size() / 3);
  std::vector<uint32_t> remap(positions.size() / 3);
  welded.clear();
  for (size_t v = 0; v < positions.size() / 3; ++v) {
    const Key k{bits(positions[3 * v]), bits(positions[3 * v + 1]), bits(positions[3 * v + 2])};
    auto [it, inserted] = map.try_emplace(k, uint32_t(welded.size() / 3));
    if (inserted) welded.insert(welded.end(), {positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]});
    remap[v] = it->second;
  }
  std::vector<uint32_t> out(indices.size());
  for (size_t i = 0; i < indices.size(); ++i) out[i] = remap[indices[i]];
  return out;
}

}  // namespace limn
