// Fuzz target: heightfield images: the bytes are written to a file (named as in fuzz_image.cpp) and
// loaded as the "filename" of a heightfield shape, which reads the image raw and builds the
// heightfield (checks of the heights and extents, the maximum mipmap, the Embree user geometry).
#include <stdexcept>
#include "core/io/scene_loader.h"
#include "fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const bool tga = size > 0 && data[size - 1] % 4 == 0;
  const std::string path = limn_fuzz::write_file(tga ? "height.tga" : "height.img", data, size);
  const std::string scene = R"({"sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}},
                                "terrain": {"type": "heightfield", "filename": ")" + path + R"(", "height_scale": 0.5}})";
  try {
    limn::load_scene_text(scene, "<fuzz>", limn_fuzz::scratch());
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
