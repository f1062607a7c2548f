// Chains of delta vertices for the boundary terms (core/diff/terms/delta_chains.h): the virtual
// camera of a flat mirror projects a point where the real camera's reflected ray passes through
// it, a glass slab's refraction stack connects a floor point to the eye along a path obeying
// Snell's law, and its area-to-solid-angle Jacobian matches central differences of that path.
#include <doctest/doctest.h>

#include "core/diff/ad/film_projection.h"
#include "core/diff/terms/delta_chains.h"
#include "core/io/scene_loader.h"
#include "core/math/frame.h"
#include "core/math/rng.h"

using namespace limn;

namespace {

std::unique_ptr<Scene> load(const std::string& shapes) {
  const std::string text = R"({
    "type": "scene",
    "sensor": {"type": "perspective", "fov": 40, "film": {"type": "hdrfilm", "width": 16, "height": 16},
               "to_world": {"look_at": {"origin": [0, 0, 2.5], "target": [0, 0, 0], "up": [0, 1, 0]}}},
    "floor": {"type": "rectangle", "to_world": {"scale": 3}},
    "ball": {"type": "sphere", "center": [-1.5, 0, 0.5], "radius": 0.2},)" + shapes + "}";
  return load_scene_dict(nlohmann::json::parse(text), "<test>", ".");
}

}  // namespace

TEST_CASE("delta chains: a tilted flat mirror's virtual camera projects through the reflection") {
  // The mirror, tilted 20 degrees about x, fills the view; the floor is behind it.
  auto scene = load(R"("mirror": {"type": "rectangle", "to_world": [{"rotate": {"axis": [1, 0, 0], "angle": 20}}, {"translate": [0, 0, 1]}],
                        "bsdf": {"type": "conductor"}})");
  const DiffParams params(*scene, {"ball.center"});
  const DeltaChains chains = find_delta_chains(*scene, params);
  REQUIRE(chains.mirror_cameras.size() == 1);
  CHECK(chains.stacks.empty());
  CHECK(chains.notes.empty());
  const FilmProjection virt(chains.mirror_cameras[0]);
  Pcg32 rng(7, 1);
  int checked = 0;
  for (int i = 0; i < 200; ++i) {
    // Points in front of the mirror (above the plane z = 1 + y tan 20 degrees).
    const Vec3 x(3.0f * rng.next_float() - 1.5f, 3.0f * rng.next_float() - 1.5f, 1.6f + 1.5f * rng.next_float());
    glm::dvec2 film;
    double unused;
    if (!virt.film_position(x, 1.0, film, unused) || !scene->camera.film_covers(film.x, film.y)) continue;
    const Ray r = scene->camera.generate_ray(Vec2(float(film.x), float(film.y)));
    SurfaceInteraction si;
    REQUIRE(scene->intersect(r, si));
    if (scene->shapes[si.shape].id != "mirror") continue;
    const Vec3 d = reflect(-r.d, si.ng);
    const Vec3 rel = x - si.p;
    // The reflected ray passes through x (1e-5: float film positions and hit points).
    CHECK(glm::length(rel - glm::dot(rel, d) * d) < 1e-5f * (1.0f + glm::length(rel)));
    CHECK(glm::dot(rel, d) > 0.0f);
    checked++;
  }
  CHECK(checked > 20);
}

TEST_CASE("delta chains: a periscope of two mirrors composes the reflections in the camera's order") {
  // Mirror 1 sends the camera's downward rays along +y, mirror 2 sends them up.
  auto scene = load(R"("m1": {"type": "rectangle", "to_world": [{"scale": 0.6}, {"rotate": {"axis": [1, 0, 0], "angle": -45}}, {"translate": [0, 0, 1]}],
                        "bsdf": {"type": "conductor"}},
                       "m2": {"type": "rectangle", "to_world": [{"scale": 0.6}, {"rotate": {"axis": [1, 0, 0], "angle": 45}}, {"translate": [0, 2, 1]}],
                        "bsdf": {"type": "conductor"}})");
  const DiffParams params(*scene, {"ball.center"});
  const DeltaChains chains = find_delta_chains(*scene, params);
  REQUIRE(chains.mirror_cameras.size() == 2);
  REQUIRE(chains.mirror_chains.size() == 2);
  size_t two = chains.mirror_chains[0].shapes.size() == 2 ? 0 : 1;
  REQUIRE(chains.mirror_chains[two].shapes.size() == 2);
  CHECK(scene->shapes[size_t(chains.mirror_chains[two].shapes[0])].id == "m1");
  const FilmProjection virt(chains.mirror_cameras[two]);
  Pcg32 rng(5, 3);
  int checked = 0;
  for (int i = 0; i < 400; ++i) {
    const Vec3 x(0.8f * rng.next_float() - 0.4f, 1.6f + 0.8f * rng.next_float(), 1.8f + 1.5f * rng.next_float());  // above mirror 2
    glm::dvec2 film;
    double unused;
    if (!virt.film_position(x, 1.0, film, unused) || !scene->camera.film_covers(film.x, film.y)) continue;
    Ray r = scene->camera.generate_ray(Vec2(float(film.x), float(film.y)));
    SurfaceInteraction a, b;
    if (!scene->intersect(r, a) || scene->shapes[a.shape].id != "m1") continue;
    const Vec3 d1 = reflect(-r.d, a.ng);
    if (!scene->intersect(spawn_ray(a, d1), b) || scene->shapes[b.shape].id != "m2") continue;
    const Vec3 d2 = reflect(-d1, b.ng);
    const Vec3 rel = x - b.p;
    CHECK(glm::length(rel - glm::dot(rel, d2) * d2) < 1e-5f * (1.0f + glm::length(rel)));  // float film positions and hits
    CHECK(glm::dot(rel, d2) > 0.0f);
    checked++;
  }
  CHECK(checked > 20);
}

TEST_CASE("delta chains: a glass slab's connection obeys Snell's law and its Jacobian matches central differences") {
  auto scene = load(R"("glass": {"type": "cube", "to_world": [{"scale": [1.5, 1.5, 0.1]}, {"translate": [0, 0, 1.2]}],
                       "bsdf": {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}})");
  const DiffParams params(*scene, {"ball.center"});
  const DeltaChains chains = find_delta_chains(*scene, params);
  REQUIRE(chains.stacks.size() == 1);
  const RefractionStack& st = chains.stacks[0];
  REQUIRE(st.offsets.size() == 2);
  CHECK(st.offsets[0] == doctest::Approx(-1.3).epsilon(1e-5));  // n points down, along the camera rays
  CHECK(st.offsets[1] == doctest::Approx(-1.1).epsilon(1e-5));
  CHECK(st.ior[1] == doctest::Approx(1.5).epsilon(1e-5));
  CHECK(st.ior[2] == doctest::Approx(1.0).epsilon(1e-5));
  const Vec3 eye = scene->camera.world_from_camera.point(Vec3(0.0f));
  Pcg32 rng(3, 2);
  for (int i = 0; i < 20; ++i) {
    const Vec3 y(1.6f * rng.next_float() - 0.8f, 1.6f * rng.next_float() - 0.8f, 0.0f);
    SurfaceInteraction si;
    REQUIRE(scene->intersect(Ray{y + Vec3(0, 0, 0.5f), Vec3(0, 0, -1), 0.0f, kInfinity}, si));
    Vec3 d_eye, d_last;
    double J;
    Spectrum T;
    uint64_t rays = 0;
    REQUIRE(connect_through_stack(*scene, st, si, d_eye, d_last, J, T, rays));
    // A parallel slab: the path leaves as it came in, displaced sideways.
    CHECK(glm::length(d_eye - d_last) < 1e-5f);
    // Both Fresnel transmissions, near normal incidence ~0.96 each.
    CHECK(T.x > 0.88f);
    CHECK(T.x < 0.93f);
    // The slab shifts the straight line from the eye: the refracted path meets the floor closer
    // to the axis than the straight direction to y.
    const Vec3 straight = glm::normalize(si.p - eye);
    if (glm::length(Vec2(y.x, y.y)) > 0.2f) CHECK(std::abs(d_eye.z) < std::abs(straight.z) + 1e-6f);
    // d omega / dA by central differences of the eye direction over the floor (h = 1e-3: the
    // root is solved to 1e-12, float positions of y limit the difference to ~1e-4).
    const float h = 1e-3f;
    Vec3 d[4];
    const Vec3 offs[4] = {{h, 0, 0}, {-h, 0, 0}, {0, h, 0}, {0, -h, 0}};
    for (int k = 0; k < 4; ++k) {
      SurfaceInteraction sk = si;
      sk.p = si.p + offs[k];
      Vec3 dl;
      double Jk;
      Spectrum Tk;
      REQUIRE(connect_through_stack(*scene, st, sk, d[k], dl, Jk, Tk, rays));
    }
    const glm::dvec3 du = (glm::dvec3(d[0]) - glm::dvec3(d[1])) / (2.0 * h), dv = (glm::dvec3(d[2]) - glm::dvec3(d[3])) / (2.0 * h);
    const double J_fd = std::abs(glm::dot(glm::cross(du, dv), glm::dvec3(d_eye)));
    CHECK(J_fd == doctest::Approx(J).epsilon(2e-3));
  }
}

TEST_CASE("delta chains: a curved mirror has none, and the notes name it") {
  auto scene = load(R"("mirror": {"type": "sphere", "center": [0, 0, 0.5], "radius": 0.5, "bsdf": {"type": "conductor"}})");
  const DiffParams params(*scene, {"ball.center"});
  const DeltaChains chains = find_delta_chains(*scene, params);
  CHECK(chains.mirror_cameras.empty());
  REQUIRE(chains.notes.size() == 1);
  CHECK(chains.notes[0].find("'mirror' is curved") != std::string::npos);
}
