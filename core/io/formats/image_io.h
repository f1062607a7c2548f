// Image files through OpenImageIO. Images in memory are linear RGB float; 8- and 16-bit formats
// (PNG, JPEG) are sRGB-encoded on disk and converted on the way in and out.
#pragma once
#include <string>
#include "core/render/integrators/render.h"
#include "core/render/textures/texture.h"

namespace limn {

// Reads any OpenImageIO format as linear RGB (grey is broadcast, alpha dropped). `raw` skips the
// sRGB decoding of integer formats (for data such as height or roughness maps).
// Throws std::invalid_argument naming the file on failure.
Bitmap read_image(const std::string& path, bool raw = false);
// Writes by extension: .exr and .hdr keep floats; other formats are clamped, sRGB-encoded, 8-bit.
void write_image(const std::string& path, const Image& image);

float srgb_to_linear(float v);
float linear_to_srgb(float v);

}  // namespace limn
