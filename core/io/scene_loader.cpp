#include "core/io/scene_loader.h"

#include <fstream>
#include <limits>
#include "core/io/image_io.h"
#include "core/io/scene/bsdfs.h"
#include "core/io/scene/props.h"
#include "core/io/scene/shapes.h"

namespace limn {

using namespace io_detail;

namespace {

// ---- emitters, sensor, integrator -------------------------------------------------------------------
void load_emitter(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("emitter", id, type));
  Emitter e;
  e.id = id;
  if (type == "point") {
    PointEmitter pe;
    pe.position = p.has("position") ? p.vec3("position", Vec3(0.0f)) : p.transform("to_world").point(Vec3(0.0f));
    pe.intensity = p.spectrum("intensity", Spectrum(1.0f));
    e.model = pe;
  } else if (type == "directional") {
    DirectionalEmitter de;
    const Vec3 d = p.has("direction") ? p.vec3("direction", Vec3(0, 0, 1)) : p.transform("to_world").vector(Vec3(0, 0, 1));
    if (!(glm::length(d) > 0.0f)) p.fail("direction must be non-zero");
    de.direction = glm::normalize(d);
    de.irradiance = p.spectrum("irradiance", Spectrum(1.0f));
    e.model = de;
  } else if (type == "constant") {
    e.model = ConstantEmitter{p.spectrum("radiance", Spectrum(1.0f))};
  } else if (type == "envmap") {
    EnvmapEmitter env;
    const std::string path = p.file("filename");
    try {
      env.image = std::make_shared<Bitmap>(read_image(path, false));
    } catch (const std::invalid_argument& err) {
      p.fail(err.what());
    }
    env.world_from_env = p.transform("to_world");
    float unused_scale;
    check_similarity(p, env.world_from_env, unused_scale);  // a shear would break the 2 pi^2 sin(theta) Jacobian
    env.scale = p.number("scale", 1.0f);
    if (!(env.scale >= 0.0f)) p.fail("scale must be >= 0 (got " + std::to_string(env.scale) + ")");
    e.model = std::move(env);
  } else if (type == "area") {
    p.fail("an 'area' emitter must be nested inside a shape");
  } else {
    p.fail("unknown emitter type '" + type + "' (known: " + known_of(Category::Emitter) + ")");
  }
  p.check_unused();
  ctx.scene->emitters.push_back(std::move(e));
}

void load_sensor(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("sensor", id, type));
  if (type != "perspective") p.fail("unknown sensor type '" + type + "' (known: perspective)");
  Camera& cam = ctx.scene->camera;
  cam.width = 768;
  cam.height = 576;
  for (const auto& [key, child] : p.children()) {
    const std::string ctype = type_of(*child);
    p.mark_used(key);
    if (ctype == "hdrfilm") {
      Props fp(ctx, *child, describe("film", key, ctype));
      cam.width = fp.integer("width", 768);
      cam.height = fp.integer("height", 576);
      if (cam.width <= 0 || cam.height <= 0 || cam.width > 32768 || cam.height > 32768)
        fp.fail("width and height must be in [1, 32768] (got " + std::to_string(cam.width) + " x " + std::to_string(cam.height) + ")");
      for (const auto& [fk, fchild] : fp.children()) {
        fp.mark_used(fk);
        const std::string ft = type_of(*fchild);
        if (ft != "box") ctx.scene->warnings.push_back(ctx.source + ": film '" + key + "': reconstruction filter '" + ft +
                                                       "' is not supported; limn averages samples uniformly over each pixel (box)");
      }
      fp.mark_used("pixel_format");
      fp.mark_used("component_format");
      fp.check_unused();
    } else if (known_types().count(ctype) && known_types().at(ctype) == Category::Sampler) {
      Props sp(ctx, *child, describe("sampler", key, ctype));
      ctx.scene->spp = sp.integer("sample_count", 4);
      if (ctx.scene->spp <= 0) sp.fail("sample_count must be > 0 (got " + std::to_string(ctx.scene->spp) + ")");
      if (ctype != "independent") ctx.scene->warnings.push_back(ctx.source + ": sampler '" + key + "': '" + ctype + "' is rendered with independent samples");
      sp.mark_used("seed");
      sp.check_unused();
    } else {
      p.fail("a '" + ctype + "' cannot be nested in a sensor (under '" + key + "')");
    }
  }
  cam.world_from_camera = p.transform("to_world");
  try {
    cam.set_fov(p.number("fov", 39.3077f), p.string("fov_axis", "x"));
  } catch (const std::invalid_argument& e) {
    p.fail(e.what());
  }
  cam.near_clip = p.number("near_clip", 1e-2f);
  cam.far_clip = p.number("far_clip", 1e4f);
  if (!(cam.near_clip > 0.0f && cam.far_clip > cam.near_clip)) p.fail("need 0 < near_clip < far_clip");
  p.check_unused();
}

void load_integrator(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("integrator", id, type));
  IntegratorSettings& s = ctx.scene->integrator;
  s.type = type;
  s.hide_emitters = p.boolean("hide_emitters", false);
  if (type == "path") {
    s.max_depth = p.integer("max_depth", -1);
    s.rr_depth = p.integer("rr_depth", 5);
    if (s.max_depth < -1) p.fail("max_depth must be -1 (unbounded) or >= 0 (got " + std::to_string(s.max_depth) + ")");
    if (s.rr_depth < 1) p.fail("rr_depth must be >= 1 (got " + std::to_string(s.rr_depth) + ")");
  } else if (type == "direct") {
    s.max_depth = 2;  // emitters seen directly plus one bounce
    s.rr_depth = std::numeric_limits<int>::max();
    const int ne = p.integer("emitter_samples", 1), nb = p.integer("bsdf_samples", 1);
    if (ne < 0 || ne > 1 || nb < 0 || nb > 1 || ne + nb == 0)
      p.fail("emitter_samples and bsdf_samples must each be 0 or 1, not both 0 (got " + std::to_string(ne) + ", " + std::to_string(nb) + ")");
    s.emitter_sampling = ne == 1;
    s.bsdf_sampling = nb == 1;
  } else {
    p.fail("unknown integrator type '" + type + "' (known: path, direct)");
  }
  p.check_unused();
}

}  // namespace

namespace {
std::unique_ptr<Scene> load_scene_dict_impl(const json& d, const std::string& source, const std::filesystem::path& base_dir,
                                            const std::vector<ArrayData>& arrays) {
  auto scene = std::make_unique<Scene>();
  scene->source = source;
  Context ctx{source, base_dir, &arrays, scene.get(), {}, {}};
  if (!d.is_object()) throw std::invalid_argument(source + ": the scene description must be a dictionary");
  if (d.contains("type") && d.at("type") != "scene")
    throw std::invalid_argument(source + ": top-level \"type\" must be \"scene\" (got " + d.at("type").dump() + ")");

  // Classify the top-level objects, then load in dependency order: bsdfs (shapes may refer to them),
  // shapes (area emitters live in them), the rest.
  std::vector<std::pair<std::string, const json*>> by_cat[16];
  for (auto it = d.begin(); it != d.end(); ++it) {
    if (it.key() == "type") continue;
    const json& v = it.value();
    if (!v.is_object() || !v.contains("type") || !v.at("type").is_string())
      throw std::invalid_argument(source + ": '" + it.key() + "' must be an object with a \"type\" (got " + v.dump().substr(0, 80) + ")");
    const std::string type = v.at("type").get<std::string>();
    auto cat = known_types().find(type);
    if (cat == known_types().end() || cat->second == Category::Scene || cat->second == Category::Texture || cat->second == Category::Ref)
      throw std::invalid_argument(source + ": '" + it.key() + "' has unknown type '" + type + "' (known: sensors " + known_of(Category::Sensor) +
                                  "; integrators " + known_of(Category::Integrator) + "; shapes " + known_of(Category::Shape) + "; bsdfs " +
                                  known_of(Category::Bsdf) + "; emitters " + known_of(Category::Emitter) + ")");
    if (v.contains("id") && !v.at("id").is_string()) throw std::invalid_argument(source + ": '" + it.key() + "': \"id\" must be a string");
    const std::string id = str_field(v, "id", it.key());
    if (!ctx.ids.insert(id).second) throw std::invalid_argument(source + ": duplicate id '" + id + "'");
    by_cat[int(cat->second)].emplace_back(id, &v);
  }
  for (const auto& [id, j] : by_cat[int(Category::Bsdf)]) ctx.named_bsdfs[id] = add_bsdf(ctx, load_bsdf(ctx, *j, id));
  for (const auto& [id, j] : by_cat[int(Category::Shape)]) load_shape(ctx, *j, id);
  for (const auto& [id, j] : by_cat[int(Category::Emitter)]) load_emitter(ctx, *j, id);
  const auto& sensors = by_cat[int(Category::Sensor)];
  if (sensors.empty()) throw std::invalid_argument(source + ": the scene has no sensor (add a 'perspective' sensor)");
  if (sensors.size() > 1) scene->warnings.push_back(source + ": " + std::to_string(sensors.size()) + " sensors; only '" + sensors[0].first + "' is used");
  load_sensor(ctx, *sensors[0].second, sensors[0].first);
  const auto& integrators = by_cat[int(Category::Integrator)];
  if (integrators.size() > 1) throw std::invalid_argument(source + ": more than one integrator");
  if (!integrators.empty()) load_integrator(ctx, *integrators[0].second, integrators[0].first);
  for (int c : {int(Category::Film), int(Category::Sampler), int(Category::Filter)})
    for (const auto& [id, j] : by_cat[c]) throw std::invalid_argument(source + ": '" + id + "' (" + type_of(*j) + ") must be nested in the sensor");
  if (scene->emitters.empty()) scene->warnings.push_back(source + ": the scene has no emitters; it will render black");

  scene->build();
  return scene;
}
}  // namespace

std::unique_ptr<Scene> load_scene_dict(const json& d, const std::string& source, const std::filesystem::path& base_dir,
                                       const std::vector<ArrayData>& arrays) {
  try {
    return load_scene_dict_impl(d, source, base_dir, arrays);
  } catch (const json::exception& e) {  // a wrong JSON type that a check above did not anticipate
    throw std::invalid_argument(source + ": malformed scene description: " + e.what());
  } catch (const std::filesystem::filesystem_error& e) {
    throw std::invalid_argument(source + ": " + e.what());
  }
}

std::unique_ptr<Scene> load_scene_file(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::invalid_argument("scene file '" + path + "' not found or not readable");
  json d;
  try {
    d = json::parse(f);
  } catch (const json::parse_error& e) {
    throw std::invalid_argument(path + ": malformed JSON: " + e.what());
  }
  std::filesystem::path base = std::filesystem::path(path).parent_path();
  return load_scene_dict(d, path, base.empty() ? std::filesystem::path(".") : base);
}

}  // namespace limn
