// Fuzz target: scene descriptions as JSON text, through both entry points of the loader:
//  - load_scene_text, what limn.load (load_scene_file) runs on a file's bytes;
//  - nlohmann::json::parse then load_scene_dict, what limn.load_dict runs (bindings/src/module.cpp,
//    load_json), with a few arrays passed alongside as numpy arrays would be ({"__limn_array__": i}).
// Scenes may name the valid files of the scratch folder (mesh.ply, mesh.obj, tex.png, env.exr,
// height.png). Loading builds the scene (Embree BVH, heightfield mipmaps); nothing is rendered.
#include <stdexcept>
#include "core/io/scene_loader.h"
#include "fuzz_common.h"

namespace {
std::vector<limn::ArrayData> arrays() {
  using limn::ArrayData;
  return {
      ArrayData{{3, 3}, {0, 0, 1, 1, 0, 1, 0, 1, 1}, false},               // 0: vertex positions
      ArrayData{{1, 3}, {0, 1, 2}, true},                                  // 1: faces
      ArrayData{{4, 4}, {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}, false},  // 2: a matrix
      ArrayData{{3, 3}, {0, 0.1, 0, 0.2, 0.5, 0.1, 0, 0.1, 0}, false},     // 3: heights
      ArrayData{{1, 3, 2}, {0, 0, 1, 0, 0, 1}, false},                     // 4: corner uvs
      ArrayData{{3}, {0.5, 0.25, 1}, false},                               // 5: a vector or colour
      ArrayData{{0, 3}, {}, false},                                        // 6: empty
  };
}
}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  limn_fuzz::write_valid_files();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::vector<limn::ArrayData> passed = arrays();
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    limn::load_scene_text(text, "<fuzz>", limn_fuzz::scratch(), passed);
  } catch (const std::invalid_argument&) {
  }
  const nlohmann::json j = nlohmann::json::parse(text.begin(), text.end(), nullptr, false);
  if (!j.is_discarded()) {
    try {
      limn::load_scene_dict(j, "<fuzz>", limn_fuzz::scratch(), passed);
    } catch (const std::invalid_argument&) {
    }
  }
  return 0;
}
