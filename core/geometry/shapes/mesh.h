// Triangle mesh in world space. Vertices are welded by position, so edges shared by two triangles
// are adjacent even across UV seams; texture coordinates are kept per triangle corner.
#pragma once
#include <embree3/rtcore.h>
#include <string>
#include <vector>
#include "core/geometry/parameter.h"
#include "core/geometry/ray.h"
#include "core/math/distribution.h"

namespace limn {

struct PositionSample {
  Vec3 p, n;        // point and unit surface normal
  Vec2 uv;
  float pdf_area;   // density with respect to surface area
  int prim = 0;     // triangle (meshes) ...
  Vec2 bary{0.0f};  // ... and its barycentrics (b1, b2): the point's material coordinates
};

// An undirected edge of the welded mesh with the triangles around it.
// Triangles are counted once per vertex set: a scan's duplicated triangle (either winding) is one
// surface, and counting it twice would make its edges look non-manifold.
struct MeshEdge {
  uint32_t a, b;        // vertices, a < b
  int face0, face1;     // first two distinct triangles (face1 = -1 on a boundary edge)
  int face_count;       // distinct triangles: 1 boundary, 2 manifold, more non-manifold
  uint32_t more = 0;    // non-manifold: the others are Mesh::edge_more_faces[more .. more + face_count - 2)
};

struct Mesh {
  static constexpr const char* kind_name = "mesh";
  static constexpr bool can_emit = true;

  std::vector<float> positions;      // 3 floats per vertex, world space (differentiable later)
  std::vector<uint32_t> indices;     // 3 per triangle
  std::vector<float> corner_uvs;     // 6 floats per triangle (may be empty)
  bool face_normals = false;         // true: flat shading; false: area-weighted vertex normals

  // Derived state, recomputed by update_derived() after positions change.
  std::vector<Vec3> vertex_normals;
  std::vector<uint32_t> vertex_face_offsets, vertex_faces;  // CSR: triangles around each vertex
  std::vector<int> distinct;                                 // per triangle: itself, or the first with the same corners
  std::vector<MeshEdge> edges;                               // built once: the topology is fixed (duplicates left out)
  std::vector<int> edge_more_faces;                          // non-manifold edges' third and later triangles
  // Per triangle +1 or -1: the flips that make windings agree across two-triangle edges, each
  // connected part turned so that a closed part encloses positive volume (its normals point out)
  // and an open part keeps the winding of most of its area; a duplicate triangle gets its twin's
  // orientation. Built once with the edges. Scans and artists' meshes have flipped triangles, and
  // convexity and facing tests need normals that agree (rendering is two-sided and does not).
  std::vector<int8_t> orientation;  // a non-orientable part keeps one seam where windings disagree
  // A triangle's sign in the smooth vertex normals (primal and derivative alike): its orientation,
  // 0 for a duplicate, which its first twin stands for.
  int normal_sign(size_t f) const { return distinct[f] == int(f) ? orientation[f] : 0; }
  std::vector<float> triangle_areas;
  Distribution1D area_distribution;  // triangles by area
  float total_area = 0.0f;

  size_t vertex_count() const { return positions.size() / 3; }
  size_t triangle_count() const { return indices.size() / 3; }
  Vec3 vertex(uint32_t i) const { return Vec3(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]); }
  // Unit normal of triangle f from its winding, in double precision.
  Vec3d face_normal(int f) const {
    const Vec3 p0 = vertex(indices[3 * f]), p1 = vertex(indices[3 * f + 1]), p2 = vertex(indices[3 * f + 2]);
    return glm::normalize(glm::cross(Vec3d(p1 - p0), Vec3d(p2 - p0)));
  }

  // Whether triangle f encloses no area (repeated corners, or corners on a line); computed in
  // double so that coordinates near the float range (1e38) neither overflow nor cancel.
  bool degenerate(size_t f) const {
    const uint32_t a = indices[3 * f], b = indices[3 * f + 1], c = indices[3 * f + 2];
    if (a == b || b == c || a == c) return true;
    const Vec3d pa(vertex(a)), n = glm::cross(Vec3d(vertex(b)) - pa, Vec3d(vertex(c)) - pa);
    return !(glm::dot(n, n) > 0.0);
  }

  // face_normal turned by `orientation`: agrees with the neighbours' across every manifold edge.
  Vec3d oriented_normal(int f) const { return double(orientation[size_t(f)]) * face_normal(f); }

  // Calls f(face) for every distinct triangle at edge e.
  template <typename F>
  void for_each_edge_face(const MeshEdge& e, F&& f) const {
    f(e.face0);
    if (e.face1 >= 0) f(e.face1);
    for (int k = 0; k + 2 < e.face_count; ++k) f(edge_more_faces[e.more + size_t(k)]);
  }

  void update_derived();
  void orient();  // fills `orientation` from the edges (called by update_derived)
  // Surface record at barycentrics (b1, b2) of triangle `prim`.
  void fill_interaction(int prim, float b1, float b2, SurfaceInteraction& si) const;

  // ---- the shape interface (core/geometry/shapes/shape.h) ----
  void build_derived() { update_derived(); }  // once after loading
  // Embree triangle geometry with its own vertex buffer, refit when the vertices move.
  RTCGeometry create_embree_geometry(RTCDevice device) const;
  void update_embree_geometry(RTCGeometry g) const;  // uploads the vertices
  // Embree's hit (triangle prim, barycentrics uv) as a surface record.
  void fill_hit(const Ray& ray, float t, unsigned prim, const Vec2& uv, SurfaceInteraction& si) const {
    fill_interaction(int(prim), uv.x, uv.y, si);
  }
  float area() const { return total_area; }
  PositionSample sample_position(const Vec2& u, float u_tri) const;
  // "<id>.vertex_positions" (N x 3, world space).
  void list_parameters(const std::string& id, int index, std::vector<Parameter>& out);
  void validate_parameter(const Parameter& p, const std::string& where) const;
  void apply_parameter(const Parameter& p) { update_derived(); }
  void translate(const Vec3& delta);
  // World-space bounding box (empty: lo > hi).
  void bounds(Vec3& lo, Vec3& hi) const;
  // Values whose change means the surface moved, and their bounding box (guide reuse).
  void geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const;
};

// Welds vertices with bitwise-equal positions; returns the new index buffer and fills `welded`.
std::vector<uint32_t> weld_by_position(const std::vector<float>& positions, const std::vector<uint32_t>& indices,
                                       std::vector<float>& welded);

}  // namespace limn
