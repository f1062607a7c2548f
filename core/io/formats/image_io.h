// Image files through OpenImageIO. Images in memory are linear RGB float; 8- and 16-bit formats
// (PNG, JPEG) are sRGB-encoded on disk and converted on the way in and out.
#pragma once
#include <cstdint>
#include <string>
#include "core/render/integrators/render.h"
#include "core/render/textures/texture.h"

namespace limn {

// Images with more pixels than this are refused before their pixels are read.
inline constexpr uint64_t kMaxImagePixels = uint64_t(1) << 27;  // e.g. 16384 x 8192
// Pixels (in the file's own format) may take at most this many times the file's size, plus 1 MiB.
inline constexpr uint64_t kMaxImageExpansion = 4096;
// A row (or a tile) of pixels, all channels as stored, may take at most this many bytes
// (OpenImageIO buffers hundreds of them at a time, whatever the height of the image).
inline constexpr uint64_t kMaxImageRowBytes = uint64_t(512) << 10;  // e.g. 32768 RGBA float pixels

// Reads PNG, JPEG, OpenEXR, Radiance HDR, TIFF, BMP, PNM/PFM and TGA files (recognised by their first
// bytes, TGA by its extension) through OpenImageIO as linear RGB (grey is broadcast, alpha
// dropped). `raw` skips the sRGB decoding of integer formats (for data such as height or roughness
// maps). Throws std::invalid_argument naming the file on failure: not a regular file, an unknown
// format, a truncated or corrupt file, more than kMaxImagePixels pixels or than the file can hold
// (kMaxImageExpansion), rows or tiles over kMaxImageRowBytes, a non-finite pixel.
Bitmap read_image(const std::string& path, bool raw = false);
// Writes by extension: .exr and .hdr keep floats; other formats are clamped, sRGB-encoded, 8-bit.
void write_image(const std::string& path, const Image& image);

float srgb_to_linear(float v);
float linear_to_srgb(float v);

}  // namespace limn
