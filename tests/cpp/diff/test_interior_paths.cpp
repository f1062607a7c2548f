// The interior replay of one path equals the primal path for the same random numbers. Where the
// primal path samples its vertices in the material coordinates the replay attaches them to (the
// emitter points of next-event estimation), the tape gradient of a single path also equals central
// differences of the primal path with its random numbers held fixed. (BSDF-sampled vertices move
// with the shading frame in the primal path, so there only the expectations agree: that is checked
// at image level in tests/python/test_derivatives.py.)
#include <doctest/doctest.h>

#include "core/diff/terms/interior.h"
#include "core/io/scene_loader.h"

using namespace limn;

namespace {

std::unique_ptr<Scene> inside_sphere_scene(const std::string& bsdf, const std::string& integrator) {
  const std::string text = R"({
    "type": "scene", "integrator": )" + integrator + R"(,
    "sensor": {"type": "perspective", "fov": 70,
               "to_world": {"look_at": {"origin": [0.3, -0.6, 0.1], "target": [0, 1, 0], "up": [0, 0, 1]}},
               "film": {"type": "hdrfilm", "width": 8, "height": 8}},
    "dome": {"type": "sphere", "radius": 2.0, "center": [0.1, 0.2, 0.0], "bsdf": {"type": "twosided", "bsdf": )" + bsdf + R"(}},
    "bulb": {"type": "point", "position": [0.2, 0.1, 0.6], "intensity": 3.0}})";
  return load_scene_dict(nlohmann::json::parse(text), "<test>", ".");
}

// Value and directional derivative (along `tangent` on parameter `name`) of one path, seeded by k.
struct PathProbe {
  Scene& scene;
  std::string name;
  std::vector<float> tangent;

  Spectrum primal(uint64_t k, float eps) {
    Parameter& p = *const_cast<Parameter*>(scene.find_parameter(name));
    std::vector<float> saved(p.data, p.data + p.size());
    for (size_t i = 0; i < p.size(); ++i) p.data[i] = saved[i] + eps * tangent[i];
    scene.update();
    Pcg32 rng = pixel_rng(7, k);
    const Vec2 film = Vec2(float(k % 8), float((k / 8) % 8)) + rng.next_2d();
    PathCounters c;
    const Spectrum L = path_radiance(scene, scene.camera.generate_ray(film), rng, c);
    std::copy(saved.begin(), saved.end(), p.data);
    scene.update();
    return L;
  }
  void check(uint64_t k, bool per_path_derivative) {
    const DiffParams params(scene, {name});
    Pcg32 rng = pixel_rng(7, k);
    const Vec2 film = Vec2(float(k % 8), float((k / 8) % 8)) + rng.next_2d();
    PathInputs in;
    PathCounters c;
    ad::Tape::current().clear();
    const auto L = interior_path_radiance(scene, params, scene.camera.generate_ray(film), rng, in, c, scene.integrator.max_depth);
    const Spectrum L0 = primal(k, 0.0f);
    CAPTURE(k);
    CHECK(L.x.v == doctest::Approx(L0.x).epsilon(1e-4));
    if (!per_path_derivative) return;
    std::vector<double> adj;
    double d = 0;
    if (!L.x.is_constant()) {
      ad::Tape::current().backward(L.x.idx, 1.0, adj);
      for (const auto& [node, slot] : in.nodes) d += adj[node] * tangent[slot];
    }
    const float eps = 1e-3f;
    const double fd = (double(primal(k, eps).x) - double(primal(k, -eps).x)) / (2.0 * eps);
    CAPTURE(k);
    CAPTURE(L0.x);
    // Float rounding of the primal path bounds the FD accuracy: ~1e-7 |L| / eps, kept 10x below.
    CHECK(std::abs(d - fd) <= 5e-3 * std::abs(fd) + 1e-3 * std::abs(L0.x));
  }
};

}  // namespace

TEST_CASE("interior replay: value and derivative of single paths against the primal path") {
  for (const std::string integ : {R"({"type": "direct", "bsdf_samples": 0})", R"({"type": "path", "max_depth": 3, "rr_depth": 100})",
                                  R"({"type": "path", "max_depth": 5})"}) {
    const bool nee_only = integ.find("direct") != std::string::npos;
    for (const std::string bsdf : {R"({"type": "diffuse", "reflectance": 0.6})", R"({"type": "roughconductor", "distribution": "ggx", "alpha": 0.4})"}) {
      auto scene = inside_sphere_scene(bsdf, integ);
      CAPTURE(integ);
      CAPTURE(bsdf);
      for (const auto& [name, t] : std::vector<std::pair<std::string, std::vector<float>>>{
               {"dome.radius", {1.0f}}, {"dome.center", {0.3f, -0.5f, 1.0f}}, {"bulb.intensity", {1.0f, 1.0f, 1.0f}}}) {
        CAPTURE(name);
        PathProbe probe{*scene, name, t};
        for (uint64_t k = 0; k < 24; ++k) probe.check(k, nee_only);
      }
    }
  }
}
