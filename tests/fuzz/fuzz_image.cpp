// Fuzz target: image files through limn's image reader (read_image: the format by its first bytes,
// then OpenImageIO). The bytes are written to a file, named *.tga when the last byte is a multiple of
// 4 (TGA is the one format recognised by its extension); the second-to-last byte's low bit picks raw
// (no sRGB decoding). What read_image returns must have finite pixels of the declared size.
#include <stdexcept>
#include "fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const bool tga = size > 0 && data[size - 1] % 4 == 0;
  const bool raw = size > 1 && (data[size - 2] & 1);
  const std::string path = limn_fuzz::write_file(tga ? "input.tga" : "input.img", data, size);
  try {
    const limn::Bitmap b = limn::read_image(path, raw);
    if (b.width <= 0 || b.height <= 0 || b.rgb.size() != size_t(b.width) * size_t(b.height) * 3) limn_fuzz::invariant_broken("bitmap size");
    for (float v : b.rgb)
      if (!std::isfinite(v)) limn_fuzz::invariant_broken("non-finite pixel");
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
