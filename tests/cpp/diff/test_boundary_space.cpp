// Boundary sample space of the indirect term: sample -> invert round trips, the pdf matches the
// measure of the space, silhouette conditions hold, and delta-light points graze the boundary.
#include <doctest/doctest.h>

#include "tests/cpp/test_util.h"

#include "core/diff/terms/boundary_space.h"
#include "core/diff/shapes/mesh.h"
#include "core/io/scene_loader.h"
#include "core/math/rng.h"
#include "core/math/warp.h"

#include <algorithm>
#include <array>
#include <sstream>
#include <vector>

using namespace limn;

namespace {

// Segments of each part of Eq. 4: mesh edges are the perimeter part, sphere surfaces the interior.
size_t count(const BoundarySpace& space, BoundaryPart part) {
  size_t n = 0;
  for (const BoundarySegment& s : space.segments()) n += s.part == part;
  return n;
}
const MeshEdge& edge_of(const Scene& scene, const BoundarySegment& s) {
  return test::geometry<Mesh>(scene, size_t(s.shape)).edges[size_t(s.local)];
}

std::unique_ptr<Scene> cube_and_ball() {
  const std::string text = R"({
    "type": "scene",
    "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}},
    "box": {"type": "cube", "to_world": [{"scale": 0.5}, {"translate": [1, 0, 0]}]},
    "ball": {"type": "sphere", "center": [-1, 0.5, 0.2], "radius": 0.7},
    "bulb": {"type": "point", "position": [0.5, 3, 2], "intensity": 1},
    "sun": {"type": "directional", "direction": [0.3, -0.2, -1], "irradiance": 1}})";
  return load_scene_dict(nlohmann::json::parse(text), "<test>", ".");
}

}  // namespace

TEST_CASE("boundary space: sample and invert round-trip, pdf matches the measure") {
  auto scene = cube_and_ball();
  const DiffParams params(*scene, {"box.vertex_positions", "ball.center"});
  const BoundarySpace space(*scene, params);
  CHECK(count(space, BoundaryPart::Perimeter) == 12);  // the cube's 12 convex edges; the diagonals are flat
  CHECK(count(space, BoundaryPart::Interior) == 1);

  Pcg32 rng(11);
  const int n = 200000;
  double inv_pdf_edges = 0, inv_pdf_sphere = 0;
  int ok = 0;
  for (int i = 0; i < n; ++i) {
    const Vec3 u(rng.next_float(), rng.next_float(), rng.next_float());
    BoundaryPoint p;
    if (!space.sample(u, 1.0f, p)) continue;
    ++ok;
    const BoundarySegment& s = space.segments()[size_t(p.segment)];
    (s.part == BoundaryPart::Perimeter ? inv_pdf_edges : inv_pdf_sphere) += 1.0 / p.pdf;
    CHECK(std::abs(glm::length(p.w) - 1.0f) < 1e-5f);
    CHECK(std::abs(glm::dot(p.n_b, p.w)) < 1e-5f);  // n_b is perpendicular to the boundary ray
    const Vec3 back = space.invert(p.segment, p.xb, p.w);
    BoundaryPoint q;
    REQUIRE(space.sample(back, 1.0f, q));
    CHECK(q.segment == p.segment);
    CHECK(glm::length(q.xb - p.xb) < 1e-5f);
    CHECK(glm::length(q.w - p.w) < 1e-4f);
    if (s.part == BoundaryPart::Interior) {
      CHECK(std::abs(glm::dot(p.xb - Vec3(-1, 0.5, 0.2), p.w)) < 1e-5f);  // tangent to the sphere
      CHECK(p.jacobian == doctest::Approx(1.0 / 0.7));
    }
  }
  // E[1/pdf] over accepted samples = the measure where the integrand can be non-zero: the sphere's
  // whole space (area x 2 pi) and, per cube edge (length 1, faces at right angles), the half of S^2
  // where one face looks towards w and the other away.
  const double sphere_measure = 4.0 * kPi * 0.49 * 2.0 * kPi;
  CHECK(inv_pdf_sphere / n == doctest::Approx(sphere_measure).epsilon(0.02));
  const double edge_measure = 12 * 1.0 * (4.0 * kPi * 0.5);
  CHECK(inv_pdf_edges / n == doctest::Approx(edge_measure).epsilon(0.02));
  CHECK(ok < n);
}

TEST_CASE("boundary space: delta-light points graze the boundary") {
  auto scene = cube_and_ball();
  const DiffParams params(*scene, {"ball.radius"});
  const BoundarySpace space(*scene, params);
  REQUIRE(count(space, BoundaryPart::Interior) == 1);
  CHECK(space.static_count() == 12);  // the cube does not move, its edges take part
  for (const Emitter& light : scene->emitters) {
    Pcg32 rng(5);
    double length = 0;
    const int n = 200000;
    for (int i = 0; i < n; ++i) {
      BoundaryPoint p;
      const bool ok = space.sample_delta(rng.next_float(), 1.0f, light, p);
      if (space.segments()[size_t(p.segment)].part == BoundaryPart::Perimeter) continue;  // the static cube
      REQUIRE(ok);
      const Vec3 normal = (p.xb - Vec3(-1, 0.5, 0.2)) / 0.7f;
      CHECK(std::abs(glm::length(normal) - 1.0f) < 1e-5f);
      CHECK(std::abs(glm::dot(normal, p.w)) < 1e-5f);  // the light's ray is tangent at x_b
      length += 1.0 / p.pdf;  // the sphere's share of u0 is in the pdf
    }
    // E[1/pdf over the sphere's samples] = the silhouette circle's length: 2 pi r sin(alpha).
    double sin_alpha = 1.0;
    if (const auto* pt = std::get_if<PointEmitter>(&light.model)) {
      const double d = glm::length(pt->position - Vec3(-1, 0.5, 0.2));
      sin_alpha = std::sqrt(1.0 - 0.49 / (d * d));
    }
    CHECK(length / n == doctest::Approx(2.0 * kPi * 0.7 * sin_alpha).epsilon(0.02));
  }
}

TEST_CASE("boundary space: edges follow each other in space, whatever the mesh's face order") {
  // A bumpy 24 x 24 sheet whose triangles are listed in random order (like a scanned mesh): the
  // space orders edges by the Morton code of their midpoints, so 32 consecutive segments (about
  // one guide slab) cover a small patch; in face order they span most of the sheet.
  const int n = 24;
  std::ostringstream v, f;
  v << "[";
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const float x = float(i) / (n - 1), y = float(j) / (n - 1);
      v << (i + j ? "," : "") << "[" << x << "," << y << "," << 0.1f * std::sin(9.0f * x) * std::cos(7.0f * y) << "]";
    }
  v << "]";
  std::vector<std::array<int, 3>> tris;
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const int a = j * n + i;
      tris.push_back({a, a + 1, a + n + 1});
      tris.push_back({a, a + n + 1, a + n});
    }
  Pcg32 rng(4);
  for (size_t k = tris.size() - 1; k > 0; --k) std::swap(tris[k], tris[size_t(rng.next_float() * (k + 1)) % (k + 1)]);
  f << "[";
  for (size_t k = 0; k < tris.size(); ++k) f << (k ? "," : "") << "[" << tris[k][0] << "," << tris[k][1] << "," << tris[k][2] << "]";
  f << "]";
  const std::string text = R"({"type": "scene", "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}},
      "sheet": {"type": "mesh", "vertex_positions": )" + v.str() + R"(, "faces": )" + f.str() + "}}";
  auto scene = load_scene_dict(nlohmann::json::parse(text), "<test>", ".");
  const DiffParams params(*scene, {"sheet.vertex_positions"});
  const BoundarySpace space(*scene, params);
  const Mesh& m = test::geometry<Mesh>(*scene, 0);
  REQUIRE(count(space, BoundaryPart::Perimeter) > 500);
  // Median extent (in x, y) of 32 consecutive edge midpoints of an edge sequence.
  auto median_extent = [&](const std::vector<std::pair<uint32_t, uint32_t>>& edges) {
    std::vector<float> extents;
    for (size_t start = 0; start + 32 <= edges.size(); start += 32) {
      Vec3 lo(kInfinity), hi(-kInfinity);
      for (size_t k = start; k < start + 32; ++k) {
        const Vec3 mid = 0.5f * (m.vertex(edges[k].first) + m.vertex(edges[k].second));
        lo = glm::min(lo, mid);
        hi = glm::max(hi, mid);
      }
      extents.push_back(std::max(hi.x - lo.x, hi.y - lo.y));
    }
    std::sort(extents.begin(), extents.end());
    return extents[extents.size() / 2];
  };
  std::vector<std::pair<uint32_t, uint32_t>> in_space, in_face_order;
  for (const BoundarySegment& seg : space.segments()) in_space.push_back({edge_of(*scene, seg).a, edge_of(*scene, seg).b});
  for (const MeshEdge& e : m.edges) in_face_order.push_back({e.a, e.b});
  const float ordered = median_extent(in_space), listed = median_extent(in_face_order);
  MESSAGE("median extent of 32 consecutive edges: in the space ", ordered, ", in face order ", listed);
  CHECK(ordered < 0.4f * listed);
}

TEST_CASE("mesh edges: a duplicated triangle counts once, in either winding") {
  // A tetrahedron (faces 0, 1, 3, 4) with fins on edges (0,1) (face 5) and (2,3) (face 6), and
  // duplicates: 2 of 1 (opposite winding, before the fin arrives), 7 of 5 and 8 of 6 (after it).
  const std::string text = R"({
    "type": "scene",
    "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}},
    "tet": {"type": "mesh",
            "vertex_positions": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, -1, -1], [-1, 1, 1]],
            "faces": [[0, 2, 1], [0, 1, 3], [1, 0, 3], [0, 3, 2], [1, 2, 3], [0, 1, 4], [3, 2, 5], [0, 1, 4], [2, 3, 5]]}})";
  auto scene = load_scene_dict(nlohmann::json::parse(text), "<test>", ".");
  const Mesh& m = test::geometry<Mesh>(*scene, 0);
  CHECK(m.edges.size() == 10);
  CHECK(m.edge_more_faces.size() == 2);
  for (const MeshEdge& e : m.edges) {
    std::vector<int> faces;
    m.for_each_edge_face(e, [&](int f) { faces.push_back(f); });
    std::sort(faces.begin(), faces.end());
    CHECK(int(faces.size()) == e.face_count);
    if (e.a == 0 && e.b == 1) CHECK(faces == std::vector<int>{0, 1, 5});  // before: 5 triangles
    else if (e.a == 2 && e.b == 3) CHECK(faces == std::vector<int>{3, 4, 6});
    else if (e.b >= 4) CHECK(e.face_count == 1);  // the fins' open edges
    else CHECK(e.face_count == 2);
  }
}

TEST_CASE("mesh orientation: flipped and duplicated triangles turned to agree, closed parts outward") {
  // A tetrahedron (corners 0-3) and, apart, an open strip of three triangles (4-8). Each in five
  // windings: as given, each part turned inside out, one triangle flipped, a triangle duplicated in
  // the other winding. Oriented normals must point out of the tetrahedron (away from its centroid)
  // and agree across the strip's edges with the winding of most of its area.
  const std::vector<std::array<uint32_t, 3>> tet = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}},
                                             strip = {{4, 5, 6}, {5, 7, 6}, {6, 7, 8}};
  auto flip = [](std::array<uint32_t, 3> f) { return std::array<uint32_t, 3>{f[0], f[2], f[1]}; };
  for (int variant = 0; variant < 5; ++variant) {
    CAPTURE(variant);
    std::vector<std::array<uint32_t, 3>> faces;
    for (const auto& f : tet) faces.push_back(variant == 1 ? flip(f) : f);
    for (const auto& f : strip) faces.push_back(variant == 2 ? flip(f) : f);
    if (variant == 3) faces[2] = flip(faces[2]), faces[5] = flip(faces[5]);
    if (variant == 4) faces.push_back(flip(faces[1])), faces.push_back(flip(faces[6]));
    nlohmann::json f = faces;
    const std::string text = R"({"type": "scene", "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}},
      "m": {"type": "mesh", "vertex_positions": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1],
                                                 [3, 0, 0], [4, 0, 0], [3, 1, 0.2], [4, 1, 0], [3.5, 2, 0]], "faces": )" + f.dump() + "}}";
    auto scene = load_scene_dict(nlohmann::json::parse(text), "<test>", ".");
    const Mesh& m = test::geometry<Mesh>(*scene, 0);
    REQUIRE(m.orientation.size() == faces.size());
    const Vec3d centroid(0.25, 0.25, 0.25);
    for (int t = 0; t < 4; ++t) CHECK(glm::dot(m.oriented_normal(t), Vec3d(m.vertex(m.indices[3 * t])) - centroid) > 0.0);
    // The strip's given winding (variant 0) has normals up (+z); most of its area keeps its winding.
    const double up = variant == 2 ? -1.0 : 1.0;
    for (int t = 4; t < 7; ++t) CHECK(m.oriented_normal(t).z * up > 0.5);
    if (variant == 4) {  // duplicates: the same oriented normal as their twins
      CHECK(glm::length(m.oriented_normal(7) - m.oriented_normal(1)) < 1e-9);
      CHECK(glm::length(m.oriented_normal(8) - m.oriented_normal(6)) < 1e-9);
    }
    // Convex edges of the tetrahedron are candidates whatever the winding.
    int candidates = 0;
    for (const MeshEdge& e : m.edges)
      if (e.a < 4) candidates += edge_can_be_silhouette(m, e);
    CHECK(candidates == 6);
  }
}

TEST_CASE("boundary space: a non-manifold edge is a silhouette only where its triangles lie on one side") {
  // Three fins on the edge (0,0,0)-(0,0,1), their third vertices at 0, 30 and 60 degrees around it.
  // Along w the edge bounds visibility exactly when no two fins straddle the plane through the edge
  // and w; treating the edge as open (the rule before) made it a silhouette for every w.
  const std::string text = R"({
    "type": "scene",
    "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}},
    "fins": {"type": "mesh", "vertex_positions": [[0, 0, 0], [0, 0, 1], [1, 0, 0.5], [0.8660254, 0.5, 0.5], [0.5, 0.8660254, 0.5]],
             "faces": [[0, 1, 2], [1, 0, 3], [0, 1, 4]]}})";
  auto scene = load_scene_dict(nlohmann::json::parse(text), "<test>", ".");
  const DiffParams params(*scene, {"fins.vertex_positions"});
  const BoundarySpace space(*scene, params);
  const Mesh& m = test::geometry<Mesh>(*scene, 0);
  const std::array<Vec3, 3> fin{m.vertex(2), m.vertex(3), m.vertex(4)};
  Pcg32 rng(5);
  int on_edge = 0, silhouettes = 0, expected_silhouettes = 0;
  for (int i = 0; i < 20000; ++i) {
    const Vec3 u(rng.next_float(), rng.next_float(), rng.next_float());
    BoundaryPoint p;
    const bool ok = space.sample(u, 1.0f, p);
    const BoundarySegment& s = space.segments()[size_t(p.segment)];
    if (!(edge_of(*scene, s).a == 0 && edge_of(*scene, s).b == 1)) continue;
    ++on_edge;
    const Vec3 w = warp::square_to_uniform_sphere(Vec2(u.y, u.z));
    const Vec3 n = glm::normalize(glm::cross(Vec3(0, 0, 1), w));
    int below = 0;
    for (const Vec3& c : fin) below += glm::dot(n, c - Vec3(0.0f)) < 0.0f;
    const bool one_side = below == 0 || below == 3;
    expected_silhouettes += one_side;
    silhouettes += ok;
    CHECK(ok == one_side);
    if (ok)
      for (const Vec3& c : fin) CHECK(glm::dot(p.n_b, c - p.xb) < 0.0f);  // n_b points away from every fin
  }
  CHECK(on_edge > 500);
  CHECK(expected_silhouettes > 100);
  CHECK(expected_silhouettes < on_edge - 100);
  CHECK(silhouettes == expected_silhouettes);
}
