// Fuzz target: limn's PLY reader (read_ply: ascii, binary little and big endian) on any bytes; what
// it returns must satisfy the MeshData invariants (indices in range, finite values, uvs per corner).
// Small meshes it accepts are also loaded as a shape of a scene (welding, the degeneracy test, the
// Embree build).
#include <stdexcept>
#include "core/io/scene_loader.h"
#include "fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  limn::MeshData m;
  try {
    m = limn::read_ply(std::string_view(reinterpret_cast<const char*>(data), size), "<fuzz>.ply");
  } catch (const std::invalid_argument&) {
    return 0;
  }
  limn_fuzz::check_mesh(m);
  if (m.indices.size() <= 3 * 64) {
    const std::string path = limn_fuzz::write_file("input.ply", data, size);
    const std::string scene = R"({"sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}},
                                  "m": {"type": "ply", "filename": ")" + path + R"(", "allow_degenerate": true}})";
    try {
      limn::load_scene_text(scene, "<fuzz>", limn_fuzz::scratch());
    } catch (const std::invalid_argument&) {
    }
  }
  return 0;
}
