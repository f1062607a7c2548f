#include "core/io/scene_loader.h"

#include <algorithm>
#include "core/io/formats/files.h"
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
    throw std::invalid_argument(source + ": top-level \"type\" must be \"scene\" (got " + brief(d.at("type")) + ")");

  // Classify the top-level objects, then load in dependency order: bsdfs (shapes may refer to them),
  // shapes (area emitters live in them), the rest; within each kind in the order of their keys.
  std::vector<std::pair<std::string, const json*>> top;
  for (auto it = d.begin(); it != d.end(); ++it)
    if (it.key() != "type") top.emplace_back(it.key(), &it.value());
  std::sort(top.begin(), top.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<std::pair<std::string, const json*>> by_cat[16];
  for (const auto& [key, vp] : top) {
    const json& v = *vp;
    if (!valid_id(key)) throw std::invalid_argument(source + ": the key '" + printable(key, 60) + "' is not a valid id (1 to 256 characters, no control characters)");
    if (!v.is_object() || !v.contains("type") || !v.at("type").is_string())
      throw std::invalid_argument(source + ": '" + key + "' must be an object with a \"type\" (got " + brief(v) + ")");
    const std::string type = v.at("type").get<std::string>();
    auto cat = known_types().find(type);
    if (cat == known_types().end() || cat->second == Category::Scene || cat->second == Category::Texture || cat->second == Category::Ref)
      throw std::invalid_argument(source + ": '" + key + "' has unknown type '" + printable(type, 60) + "' (known: sensors " + known_of(Category::Sensor) +
                                  "; integrators " + known_of(Category::Integrator) + "; shapes " + known_of(Category::Shape) + "; bsdfs " +
                                  known_of(Category::Bsdf) + "; emitters " + known_of(Category::Emitter) + ")");
    if (v.contains("id") && !v.at("id").is_string())
      throw std::invalid_argument(source + ": '" + key + "': \"id\" must be a string (got " + brief(v.at("id")) + ")");
    const std::string id = str_field(v, "id", key);
    if (!valid_id(id)) throw std::invalid_argument(source + ": '" + key + "': \"id\" " + brief(v.at("id")) + " is not a valid id (1 to 256 characters, no control characters)");
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
  if (integrators.size() > 1)
    throw std::invalid_argument(source + ": more than one integrator ('" + integrators[0].first + "', '" + integrators[1].first + "')");
  if (!integrators.empty()) load_integrator(ctx, *integrators[0].second, integrators[0].first);
  for (int c : {int(Category::Film), int(Category::Sampler), int(Category::Filter)})
    for (const auto& [id, j] : by_cat[c]) throw std::invalid_argument(source + ": '" + id + "' (" + type_of(*j) + ") must be nested in the sensor");
  if (scene->emitters.empty()) scene->warnings.push_back(source + ": the scene has no emitters; it will render black");

  scene->build();
  return scene;
}

// Every message leaves as valid UTF-8 (Python shows an empty message otherwise).
std::unique_ptr<Scene> load_checked(const json& d, const std::string& source, const std::filesystem::path& base_dir,
                                    const std::vector<ArrayData>& arrays) {
  try {
    return load_scene_dict_impl(d, source, base_dir, arrays);
  } catch (const std::invalid_argument& e) {
    if (valid_utf8(e.what())) throw;
    throw std::invalid_argument(printable(e.what(), 2000));
  } catch (const json::exception& e) {  // a wrong JSON type that a check did not anticipate
    throw std::invalid_argument(source + ": malformed scene description: " + printable(e.what(), 300));
  } catch (const std::filesystem::filesystem_error& e) {
    throw std::invalid_argument(source + ": " + printable(e.what(), 300));
  }
}

}  // namespace

std::unique_ptr<Scene> load_scene_dict(const nlohmann::json& d, const std::string& source, const std::filesystem::path& base_dir,
                                       const std::vector<ArrayData>& arrays) {
  return load_checked(to_ordered(d, source), source, base_dir, arrays);
}

std::unique_ptr<Scene> load_scene_text(std::string_view text, const std::string& source, const std::filesystem::path& base_dir,
                                       const std::vector<ArrayData>& arrays) {
  return load_checked(parse_scene_json(text, source), source, base_dir, arrays);
}

std::unique_ptr<Scene> load_scene_file(const std::string& path) {
  const std::string text = read_file_bytes(path, "scene file", kMaxSceneFileBytes);
  std::filesystem::path base = std::filesystem::path(path).parent_path();
  return load_scene_text(text, printable(path), base.empty() ? std::filesystem::path(".") : base);
}

}  // namespace limn
