#include "core/io/scene_loader.h"

#include <fstream>
#include "core/io/scene/bsdfs.h"
#include "core/io/scene/emitters.h"
#include "core/io/scene/props.h"
#include "core/io/scene/sensor.h"
#include "core/io/scene/shapes.h"

// The entry points and the top-level dispatch; each kind of object has its loader in core/io/scene/.
namespace limn {

using namespace io_detail;

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
