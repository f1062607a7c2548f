// Scene descriptions in Mitsuba 3's dictionary conventions, as JSON files or as dictionaries from
// Python (docs/scene-format.md). Every problem is reported as std::invalid_argument naming the
// source, the object and the bad value.
#pragma once
#include <cstdint>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>
#include "core/io/scene/array_data.h"
#include "core/render/scene.h"

namespace limn {

// Scene files larger than this are refused before they are read.
inline constexpr uint64_t kMaxSceneFileBytes = uint64_t(256) << 20;

// A JSON file: refuses what is not a regular file (a directory, a FIFO) before opening it.
std::unique_ptr<Scene> load_scene_file(const std::string& path);
// JSON text (what load_scene_file reads): nesting deeper than 256 levels, keys repeated in an
// object, invalid UTF-8 and numbers beyond double are refused with the line and column.
std::unique_ptr<Scene> load_scene_text(std::string_view text, const std::string& source, const std::filesystem::path& base_dir,
                                       const std::vector<ArrayData>& arrays = {});
// A description parsed elsewhere (nlohmann::json sorts keys, so nested objects come in key order;
// load_scene_text keeps the text's order).
std::unique_ptr<Scene> load_scene_dict(const nlohmann::json& description, const std::string& source,
                                       const std::filesystem::path& base_dir, const std::vector<ArrayData>& arrays = {});

}  // namespace limn
