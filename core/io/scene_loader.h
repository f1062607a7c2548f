// Scene descriptions in Mitsuba 3's dictionary conventions, as JSON files or as dictionaries from
// Python (docs/scene-format.md). Every problem is reported as std::invalid_argument naming the
// source, the object and the bad value.
#pragma once
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>
#include "core/io/scene/array_data.h"
#include "core/render/scene.h"

namespace limn {

std::unique_ptr<Scene> load_scene_file(const std::string& path);
std::unique_ptr<Scene> load_scene_dict(const nlohmann::json& description, const std::string& source,
                                       const std::filesystem::path& base_dir, const std::vector<ArrayData>& arrays = {});

}  // namespace limn
