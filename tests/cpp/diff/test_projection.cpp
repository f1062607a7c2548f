// Projective sampling: projections land on true silhouettes (the two faces see the segment origin
// from opposite sides; for spheres dot(n, x_b - x_a) = 0), come back through sample(invert(..)),
// and stay finite on open, non-manifold and sliver meshes.
#include <doctest/doctest.h>

#include "tests/cpp/test_util.h"

#include <sstream>
#include "core/diff/terms/projection.h"
#include "core/io/scene_loader.h"
#include "core/math/warp.h"

using namespace limn;

namespace {

std::unique_ptr<Scene> scene_with(const std::string& shapes) {
  const std::string text = R"({"type": "scene", "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}},
                              "bulb": {"type": "point", "position": [0, 0, 5]}, )" + shapes + "}";
  return load_scene_dict(nlohmann::json::parse(text), "<test>", ".");
}

struct Rates {
  int tried = 0, projected = 0, found = 0;
};

// Segments from random viewpoints on a sphere of radius `view` to the points they hit on the scene.
Rates check_projections(const Scene& scene, const BoundarySpace& space, MeshProjection mode, float view, int n) {
  const Projector proj(scene, space, mode);
  Pcg32 rng(17);
  Rates r;
  for (int i = 0; i < n; ++i) {
    const Vec3 xa = view * warp::square_to_uniform_sphere(rng.next_2d());
    const Vec3 d = glm::normalize(0.6f * warp::square_to_uniform_sphere(rng.next_2d()) - xa);
    SurfaceInteraction hit;
    if (!scene.intersect(Ray{xa, d, 0.0f, kInfinity}, hit)) continue;
    ++r.tried;
    const auto p = proj.project(xa, hit, rng);
    if (!p) continue;
    ++r.projected;
    r.found += p->found;
    REQUIRE(std::isfinite(p->u.x + p->u.y + p->u.z));
    CHECK(p->u.x >= 0.0f);
    CHECK(p->u.x < 1.0f);
    // Round trip through the boundary sample space.
    BoundaryPoint q;
    REQUIRE(space.sample(p->u, 1.0f, q));
    CHECK(q.segment == p->segment);
    CHECK(glm::length(q.xb - p->xb) < 1e-4f);
    CHECK(glm::length(q.w - p->w) < 1e-3f);
    if (!p->found) continue;
    // The boundary segment keeps the original direction where it can (x_a slides a little).
    CHECK(glm::dot(p->w, glm::normalize(xa - hit.p)) > 0.5f);
    const BoundarySegment& s = space.segments()[size_t(p->segment)];
    if (const auto* sp_ptr = std::get_if<Sphere>(&scene.shapes[s.shape].geometry)) {
      const Sphere& sp = *sp_ptr;
      CHECK(std::abs(glm::dot(glm::normalize(p->xb - sp.center), p->w)) < 1e-4f);  // tangent
      // On the silhouette seen from xa itself, too (Listing 1).
      CHECK(std::abs(glm::dot(glm::normalize(p->xb - sp.center), glm::normalize(p->xb - xa))) < 1e-4f);
    } else if (const MeshEdge& e = test::geometry<Mesh>(scene, size_t(s.shape)).edges[size_t(s.local)]; e.face_count == 2) {
      const Mesh& m = test::geometry<Mesh>(scene, size_t(s.shape));
      const double s0 = glm::dot(m.face_normal(e.face0), Vec3d(p->w)), s1 = glm::dot(m.face_normal(e.face1), Vec3d(p->w));
      CHECK(s0 * s1 < 0.0);  // one face towards w, the other away: a true silhouette for the ray
    }
  }
  return r;
}

}  // namespace

TEST_CASE("projection: spheres land on the silhouette seen from the segment origin (Listing 1)") {
  auto scene = scene_with(R"("ball": {"type": "sphere", "center": [0.1, -0.2, 0.05], "radius": 0.8})");
  const DiffParams params(*scene, {"ball.center"});
  const BoundarySpace space(*scene, params);
  const Rates r = check_projections(*scene, space, MeshProjection::Hybrid, 3.0f, 3000);
  CHECK(r.tried > 1000);
  CHECK(r.found == r.tried);
}

TEST_CASE("projection: meshes (WALK, JUMP, hybrid) find true silhouettes on smooth and bumpy spheres") {
  for (const float bump : {0.0f, 0.08f}) {
    auto scene = scene_with(R"("blob": )" + test::bumpy_sphere_json(40, 20, 0.8f, bump));
    const DiffParams params(*scene, {"blob.vertex_positions"});
    const BoundarySpace space(*scene, params);
    double found[3];
    for (MeshProjection mode : {MeshProjection::Walk, MeshProjection::Jump, MeshProjection::Hybrid}) {
      const Rates r = check_projections(*scene, space, mode, 3.0f, 2000);
      CAPTURE(bump);
      CAPTURE(int(mode));
      CHECK(r.tried > 500);
      CHECK(r.projected > 0.8 * r.tried);  // the rest: no valid snapped direction either (counted, not used)
      found[int(mode)] = double(r.found) / r.tried;
      MESSAGE("bump " << bump << ", mode " << int(mode) << ": silhouettes found for " << 100.0 * found[int(mode)] << " % of "
                      << r.tried << " segments");
    }
    // Measured on this lat-long mesh (tiny triangles near the poles need many steps): WALK 44 / 58 %,
    // JUMP 30 / 14 %, hybrid 97 / 86 % (smooth / bumpy); the hybrid is the best of the three.
    CHECK(found[2] >= found[0]);
    CHECK(found[2] >= found[1]);
    CHECK(found[2] > (bump == 0.0f ? 0.95 : 0.8));
  }
}

TEST_CASE("projection: open, non-manifold and sliver meshes stay finite") {
  // A plane with a hole's worth of open edges, a fin sharing one edge with two other triangles
  // (non-manifold) and a sliver triangle.
  auto scene = scene_with(R"(
    "sheet": {"type": "mesh", "allow_degenerate": true,
              "vertex_positions": [[-1,-1,0],[1,-1,0],[1,1,0],[-1,1,0],[0,0,0.5],[0,0,-0.5],[1,1,1e-7],[2,1,0]],
              "faces": [[0,1,2],[0,2,3],[0,2,4],[0,2,5],[2,6,7]]})");
  const DiffParams params(*scene, {"sheet.vertex_positions"});
  const BoundarySpace space(*scene, params);
  REQUIRE(!space.empty());
  const Rates r = check_projections(*scene, space, MeshProjection::Hybrid, 3.0f, 3000);
  CHECK(r.tried > 100);
  CHECK(r.projected > 0);
}

TEST_CASE("projection: on a box corner with two silhouette edges, hits go to the nearer one") {
  // A flat-shaded box seen from below, left and front: its left face is front-facing, its top and
  // back faces back-facing, so the left face's corner triangle borders two silhouette edges. Hits
  // next to the back edge must land there, hits next to the top edge there (the walk once took the
  // first edge in index order for all of them, leaving the other without projections).
  // The same box as a scan may come: the triangles across both edges in the other winding, and the
  // left face's corner triangle duplicated in the other winding (bunny.ply has both; the walk once
  // tested silhouettes by face normals, which flip with the winding, and a hit on the duplicate had
  // no neighbours).
  const char* faces_of[2] = {"[[0,2,1],[0,3,2],[4,5,6],[4,6,7],[0,1,5],[0,5,4],[1,2,6],[1,6,5],[2,3,7],[2,7,6],[3,0,4],[3,4,7]]",
                             "[[0,2,1],[0,3,2],[4,5,6],[4,7,6],[0,1,5],[0,5,4],[1,2,6],[1,6,5],[2,7,3],[2,7,6],[3,0,4],[3,4,7],[3,7,4]]"};
  for (const char* faces : faces_of) {
  CAPTURE(faces);
  auto scene = scene_with(std::string(R"(
    "box": {"type": "mesh", "face_normals": true,
            "vertex_positions": [[-0.5,-0.5,0.7],[0.5,-0.5,0.7],[0.5,0.5,0.7],[-0.5,0.5,0.7],
                                 [-0.5,-0.5,1.7],[0.5,-0.5,1.7],[0.5,0.5,1.7],[-0.5,0.5,1.7]],
            "faces": )") + faces + "}");
  const DiffParams params(*scene, {"box.vertex_positions"});
  const BoundarySpace space(*scene, params);
  const Mesh& m = test::geometry<Mesh>(*scene, 0);
  for (const MeshProjection mode : {MeshProjection::Walk, MeshProjection::Hybrid}) {
    CAPTURE(int(mode));
    const Projector proj(*scene, space, mode);
    const Vec3 xa(-1.5f, -2.0f, -1.0f);
    auto edge_of = [&](const Projection& p) {
      const BoundarySegment& s = space.segments()[size_t(p.segment)];
      const MeshEdge& e = m.edges[size_t(s.local)];
      const Vec3 a = m.vertex(e.a), b = m.vertex(e.b);
      if (a.x == -0.5f && b.x == -0.5f && a.y == 0.5f && b.y == 0.5f) return std::string("back-left");
      if (a.x == -0.5f && b.x == -0.5f && a.z == 1.7f && b.z == 1.7f) return std::string("top-left");
      return std::string("other");
    };
    Pcg32 rng(5);
    int back = 0, top = 0, tried = 0;
    for (int i = 0; i < 400; ++i) {
      const bool near_back = i % 2 == 0;
      // Points on the left face (x = -0.5) within 0.05 of the back edge (y = 0.5) or of the top edge (z = 1.7).
      const float along = rng.next_float(), off = 0.05f * rng.next_float();
      const Vec3 target = near_back ? Vec3(-0.5f, 0.5f - off, 0.75f + 0.9f * along) : Vec3(-0.5f, -0.45f + 0.9f * along, 1.7f - off);
      SurfaceInteraction hit;
      REQUIRE(scene->intersect(Ray{xa, glm::normalize(target - xa), 0.0f, kInfinity}, hit));
      REQUIRE(std::abs(hit.p.x + 0.5f) < 1e-4f);
      const auto p = proj.project(xa, hit, rng);
      REQUIRE(p);
      REQUIRE(p->found);
      ++tried;
      back += near_back && edge_of(*p) == "back-left";
      top += !near_back && edge_of(*p) == "top-left";
    }
    CHECK(back == tried / 2);
    CHECK(top == tried / 2);
  }
  }
}
