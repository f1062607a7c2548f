#include "core/io/formats/image_io.h"

#include <OpenImageIO/imageio.h>
#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <stdexcept>
#include "core/io/formats/files.h"

namespace limn {

float srgb_to_linear(float v) {
  return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}
float linear_to_srgb(float v) {
  return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}

namespace {
std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}
}  // namespace

namespace {
// The formats limn reads, recognised by their first bytes (never by the extension alone, so a file
// reaches only the reader of the format it claims to be): OpenImageIO's plugin for each.
const char* image_format(const std::string& path, const unsigned char* b, size_t n) {
  auto starts = [&](const char* magic, size_t len) { return n >= len && std::memcmp(b, magic, len) == 0; };
  if (starts("\x89PNG\r\n\x1a\n", 8)) return "png";
  if (starts("\xff\xd8\xff", 3)) return "jpeg";
  if (starts("\x76\x2f\x31\x01", 4)) return "openexr";
  if (starts("#?", 2)) return "hdr";
  if (starts("II*\0", 4) || starts("MM\0*", 4)) return "tiff";
  if (starts("BM", 2)) return "bmp";
  if (n >= 3 && b[0] == 'P' && ((b[1] >= '1' && b[1] <= '6') || b[1] == 'F' || b[1] == 'f') && std::isspace(b[2])) return "pnm";
  if (lower_extension(path) == ".tga") return "targa";  // TGA has no signature
  return nullptr;
}

// An OpenImageIO error for a message: one line, valid UTF-8, never empty.
std::string oiio_error(std::string e) {
  while (!e.empty() && (e.back() == '\n' || e.back() == ' ')) e.pop_back();
  for (size_t i = 0; (i = e.find('\n', i)) != std::string::npos;) e.replace(i, 1, "; ");
  return e.empty() ? "truncated or corrupt file" : printable(e, 300);
}

// libpng reads each chunk before IDAT whole into memory, as long as its length field says: every
// chunk must fit in the file. Returns an error, or "".
std::string check_png_chunks(const std::string& path, uint64_t file_size) {
  std::ifstream f(path, std::ios::binary);
  uint64_t at = 8;
  for (int k = 0; k < 100000 && at + 12 <= file_size; ++k) {
    unsigned char c[8];
    f.seekg(std::streamoff(at));
    if (!f.read(reinterpret_cast<char*>(c), 8)) return "cannot read the PNG chunk at byte " + std::to_string(at);
    const uint64_t length = (uint64_t(c[0]) << 24) | (uint64_t(c[1]) << 16) | (uint64_t(c[2]) << 8) | c[3];
    if (length > file_size - at - 12)
      return "the PNG chunk '" + printable(std::string_view(reinterpret_cast<char*>(c + 4), 4)) + "' at byte " + std::to_string(at) + " claims " +
             std::to_string(length) + " bytes, more than the file holds (truncated or corrupt)";
    if (std::memcmp(c + 4, "IDAT", 4) == 0 || std::memcmp(c + 4, "IEND", 4) == 0) return "";  // image data: read by rows
    at += 12 + length;
  }
  return "";
}

// OpenImageIO's BMP reader decodes an RLE image whole when the file is opened, into a buffer of
// width x height from the header, before limn sees the image size: the header is read here first.
// Returns an error, or "" when the size is within the limits and what the file can hold.
std::string check_bmp_header(const std::string& path, uint64_t file_size) {
  unsigned char h[30] = {};
  std::ifstream f(path, std::ios::binary);
  f.read(reinterpret_cast<char*>(h), sizeof h);
  if (f.gcount() < 26) return "truncated BMP header";
  auto u16 = [&](int at) { return uint32_t(h[at]) | (uint32_t(h[at + 1]) << 8); };
  auto u32 = [&](int at) { return u16(at) | (u16(at + 2) << 16); };
  const uint32_t dib = u32(14);
  uint64_t w, hgt, bits;
  if (dib == 12) {  // BITMAPCOREHEADER: 16-bit sizes
    w = u16(18), hgt = u16(20), bits = u16(24);
  } else {
    if (f.gcount() < 30) return "truncated BMP header";
    w = uint64_t(std::abs(int64_t(int32_t(u32(18))))), hgt = uint64_t(std::abs(int64_t(int32_t(u32(22))))), bits = u16(28);
  }
  if (w == 0 || hgt == 0) return "empty BMP (" + std::to_string(w) + " x " + std::to_string(hgt) + " pixels)";
  if (w * hgt > kMaxImagePixels)
    return std::to_string(w) + " x " + std::to_string(hgt) + " pixels, more than the limit of " + std::to_string(kMaxImagePixels);
  const uint64_t bytes = w * hgt * std::max<uint64_t>(bits / 8, 1);
  if (bytes > kMaxImageExpansion * file_size + (uint64_t(1) << 20))
    return std::to_string(w) + " x " + std::to_string(hgt) + " pixels, more than a file of " + std::to_string(file_size) +
           " bytes can hold (corrupt header?)";
  return "";
}

// OpenEXR allocates its table of chunk offsets from the header's data window when the file is
// opened, before limn sees the image size: so the header is read here first. Returns an error, or
// "" when the data window is within the limits and its offset table fits in the file.
std::string check_exr_header(const std::string& path, uint64_t file_size) {
  std::ifstream f(path, std::ios::binary);
  std::string h(size_t(std::min<uint64_t>(file_size, 1 << 20)), '\0');
  f.read(h.data(), std::streamsize(h.size()));
  h.resize(size_t(f.gcount()));
  auto u32 = [&](size_t at) {
    uint32_t v = 0;
    for (int k = 3; k >= 0; --k) v = (v << 8) | uint8_t(h[at + size_t(k)]);
    return v;
  };
  if (h.size() < 8) return "truncated OpenEXR header";
  const uint32_t version = u32(4);
  if ((version & 0xFF) != 2) return "unsupported OpenEXR version " + std::to_string(version & 0xFF);
  if (version & 0x800) return "deep OpenEXR images are not supported";
  if (version & 0x1000) return "multi-part OpenEXR files are not supported (save a single part)";
  const bool tiled = version & 0x200;
  const size_t max_name = (version & 0x400) ? 255 : 31;  // OpenEXR reads at most this many characters of a name
  size_t at = 8;
  bool have_window = false;
  int64_t w = 0, hgt = 0;
  int compression = 0;
  uint32_t tile_x = 0, tile_y = 0;
  uint64_t pixel_bytes = 0;  // over all channels
  for (;;) {
    const size_t name_end = h.find('\0', at);
    if (name_end == std::string::npos) return "truncated OpenEXR header";
    if (name_end == at) break;  // the empty name closes the header
    if (name_end - at > max_name) return "an OpenEXR attribute name longer than " + std::to_string(max_name) + " characters";
    const std::string name = h.substr(at, name_end - at);
    const size_t type_end = h.find('\0', name_end + 1);
    if (type_end == std::string::npos || type_end + 5 > h.size()) return "truncated OpenEXR header";
    if (type_end - name_end - 1 > max_name) return "an OpenEXR attribute type name longer than " + std::to_string(max_name) + " characters";
    const uint32_t size = u32(type_end + 1);
    const size_t value = type_end + 5;
    if (size > h.size() - value) return "truncated OpenEXR header (attribute '" + printable(name, 40) + "')";
    const std::string type = h.substr(name_end + 1, type_end - name_end - 1);
    // Fixed-size types: OpenEXR reads their value by its type, whatever size the file states, so a
    // wrong size shifts every attribute after it (a shifted size field then sized an allocation of
    // 1.4 GB; found by fuzz_heightfield).
    static const std::map<std::string, uint32_t> kFixedSize = {
        {"box2i", 16}, {"box2f", 16}, {"v2i", 8}, {"v2f", 8}, {"v2d", 16}, {"v3i", 12}, {"v3f", 12}, {"v3d", 24},
        {"float", 4}, {"double", 8}, {"int", 4}, {"compression", 1}, {"lineOrder", 1}, {"envmap", 1}, {"deepImageState", 1},
        {"m33f", 36}, {"m33d", 72}, {"m44f", 64}, {"m44d", 128}, {"chromaticities", 32}, {"rational", 8}, {"tiledesc", 9},
        {"keycode", 28}, {"timecode", 8}};
    if (const auto fixed = kFixedSize.find(type); fixed != kFixedSize.end() && size != fixed->second)
      return "the OpenEXR attribute '" + printable(name, 40) + "' of type " + type + " has size " + std::to_string(size) + " (it must be " +
             std::to_string(fixed->second) + ")";
    // Values that OpenEXR sizes by counts inside them, not by the attribute's size.
    if (type == "preview" && (size < 8 || uint64_t(u32(value)) * u32(value + 4) * 4 != size - 8))
      return "the OpenEXR preview image '" + printable(name, 40) + "' does not match its size";
    if (type == "stringvector")
      for (size_t k = 0; k < size;) {
        if (size - k < 4 || u32(value + k) > size - k - 4) return "the OpenEXR string list '" + printable(name, 40) + "' overruns its size";
        k += 4 + u32(value + k);
      }
    // ID manifests (Cryptomatte) are refused: Debian's OpenEXR 3.1 reads an 8-byte size field and
    // then size - 4 bytes, 4 more than the attribute holds, which shifts every attribute after it
    // (a shifted size field then sized a 1.4 GB allocation; found by fuzz_image). limn reads no IDs.
    if (type == "idmanifest")
      return "the OpenEXR attribute '" + printable(name, 40) + "' is an ID manifest (Cryptomatte), which limn does not read; save the image without it";
    if (type == "chlist") {
      // OpenEXR reads any channel list up to its empty name, whatever size the file states, and a
      // channel name up to 255 characters: either mismatch would shift the attributes after it.
      uint64_t list_bytes = 0;
      size_t k = value;
      while (k < value + size && h[k] != '\0') {  // name, type, pLinear, reserved, xSampling, ySampling
        const size_t end = h.find('\0', k);
        if (end == std::string::npos || end + 17 > value + size) return "truncated OpenEXR channel list '" + printable(name, 40) + "'";
        if (end - k > 255) return "an OpenEXR channel name longer than 255 characters in '" + printable(name, 40) + "'";
        list_bytes += u32(end + 1) == 1 ? 2 : 4;  // half, else uint or float
        k = end + 17;
      }
      if (k + 1 != value + size) return "the OpenEXR channel list '" + printable(name, 40) + "' does not end where its size says";
      if (name == "channels") pixel_bytes = list_bytes;
    }
    if (name == "dataWindow" && size == 16) {
      const auto i32 = [&](size_t k) { return int64_t(int32_t(u32(value + 4 * k))); };
      w = i32(2) - i32(0) + 1;
      hgt = i32(3) - i32(1) + 1;
      have_window = true;
    }
    if (name == "compression" && size == 1) {
      compression = uint8_t(h[value]);
    } else if (name == "tiles" && size == 9) {
      tile_x = u32(value);
      tile_y = u32(value + 4);
    }
    at = value + size;
  }
  if (!have_window) return "the OpenEXR header has no dataWindow";
  if (w < 1 || hgt < 1) return "empty OpenEXR data window (" + std::to_string(w) + " x " + std::to_string(hgt) + ")";
  if (uint64_t(w) * uint64_t(hgt) > kMaxImagePixels)
    return std::to_string(w) + " x " + std::to_string(hgt) + " pixels, more than the limit of " + std::to_string(kMaxImagePixels);
  // OpenEXR allocates a chunk's pixels (tile or scanline block) when it opens the file, and limn all
  // pixels: neither may take more than the file could expand to.
  const uint64_t budget = kMaxImageExpansion * file_size + (uint64_t(1) << 20);
  const uint64_t bpp = std::max<uint64_t>(pixel_bytes, 1);
  if (uint64_t(w) * uint64_t(hgt) * bpp > budget)
    return std::to_string(w) + " x " + std::to_string(hgt) + " pixels of " + std::to_string(bpp) + " bytes, more than a file of " +
           std::to_string(file_size) + " bytes can hold (corrupt header?)";
  if (tiled && (uint64_t(tile_x) * uint64_t(tile_y) > kMaxImagePixels || uint64_t(tile_x) * uint64_t(tile_y) * bpp > budget))
    return "tiles of " + std::to_string(tile_x) + " x " + std::to_string(tile_y) + " pixels, more than a file of " + std::to_string(file_size) +
           " bytes can hold (corrupt header?)";
  uint64_t chunks;
  if (tiled) {
    if (tile_x < 1 || tile_y < 1) return "the OpenEXR header has no valid tile size";
    chunks = ((uint64_t(w) + tile_x - 1) / tile_x) * ((uint64_t(hgt) + tile_y - 1) / tile_y);
  } else {
    static const int lines[] = {1, 1, 1, 16, 32, 16, 32, 32, 32, 256};  // per compression: none, rle, zips, zip, piz, pxr24, b44, b44a, dwaa, dwab
    const uint64_t per_chunk = lines[compression < 10 ? compression : 0];
    if (uint64_t(w) * per_chunk * bpp > budget)
      return "blocks of " + std::to_string(per_chunk) + " scanlines of " + std::to_string(w) + " pixels, more than a file of " +
             std::to_string(file_size) + " bytes can hold (corrupt header?)";
    chunks = (uint64_t(hgt) + per_chunk - 1) / per_chunk;
  }
  if (chunks * 8 > file_size) return "truncated OpenEXR file (" + std::to_string(chunks) + " chunks cannot fit in " + std::to_string(file_size) + " bytes)";
  return "";
}
}  // namespace

Bitmap read_image(const std::string& path, bool raw) {
  const uint64_t size = check_regular_file(path, "image file");
  const std::string name = printable(path);
  if (size == 0) throw std::invalid_argument("image '" + name + "' is empty (0 bytes)");
  unsigned char head[16] = {};
  size_t got = 0;
  {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw std::invalid_argument("cannot open image '" + name + "'");
    f.read(reinterpret_cast<char*>(head), sizeof head);
    got = size_t(f.gcount());
  }
  const char* format = image_format(path, head, got);
  if (!format)
    throw std::invalid_argument("image '" + name + "' is not a PNG, JPEG, OpenEXR, Radiance HDR, TIFF, BMP, PNM/PFM or TGA file (by its first bytes)");
  // Checks of the headers whose sizes the libraries allocate by before limn sees the image size.
  const std::string problem = std::strcmp(format, "openexr") == 0 ? check_exr_header(path, size)
                              : std::strcmp(format, "png") == 0   ? check_png_chunks(path, size)
                              : std::strcmp(format, "bmp") == 0   ? check_bmp_header(path, size)
                                                                  : std::string();
  if (!problem.empty()) throw std::invalid_argument("cannot read image '" + name + "' (" + format + "): " + problem);
  // OpenImageIO's plugins report problems through their error state, but the libraries under them
  // (OpenEXR, libtiff) may also throw.
  try {
    auto in = OIIO::ImageInput::create(format);
    if (!in) throw std::invalid_argument("cannot read image '" + name + "': no reader for " + format + " (" + oiio_error(OIIO::geterror()) + ")");
    OIIO::ImageSpec spec;
    if (!in->open(path, spec)) throw std::invalid_argument("cannot read image '" + name + "' (" + format + "): " + oiio_error(in->geterror()));
    if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
      throw std::invalid_argument("image '" + name + "' is empty (" + std::to_string(spec.width) + " x " + std::to_string(spec.height) + " pixels, " +
                                  std::to_string(spec.nchannels) + " channels)");
    if (spec.depth != 1 || spec.deep)
      throw std::invalid_argument("image '" + name + "' is a volume or deep image (depth " + std::to_string(spec.depth) + "); limn reads flat 2D images");
    const uint64_t count = uint64_t(spec.width) * uint64_t(spec.height);
    if (count > kMaxImagePixels)
      throw std::invalid_argument("image '" + name + "' has " + std::to_string(spec.width) + " x " + std::to_string(spec.height) +
                                  " pixels, more than the limit of " + std::to_string(kMaxImagePixels));
    // No format compresses real pixels better than about 1000:1 (deflate's limit): a header that
    // claims far more than the file can hold is corrupt, and is refused before memory is taken for it.
    const uint64_t native_bytes = count * uint64_t(spec.nchannels) * uint64_t(std::max<size_t>(spec.format.size(), 1));
    if (native_bytes > kMaxImageExpansion * size + (uint64_t(1) << 20))
      throw std::invalid_argument("image '" + name + "' claims " + std::to_string(spec.width) + " x " + std::to_string(spec.height) +
                                  " pixels, more than a file of " + std::to_string(size) + " bytes can hold (corrupt header?)");
    // OpenImageIO reads hundreds of rows (or tiles) at a time into a buffer of its own, whatever the
    // image's height: the size of a row and of a tile is limited too.
    const uint64_t pixel_bytes = std::max<uint64_t>(spec.pixel_bytes(true), 1);
    if (uint64_t(spec.width) * pixel_bytes > kMaxImageRowBytes)
      throw std::invalid_argument("image '" + name + "' has rows of " + std::to_string(spec.width) + " pixels of " + std::to_string(pixel_bytes) +
                                  " bytes, more than the limit of " + std::to_string(kMaxImageRowBytes) + " bytes per row");
    if (spec.tile_width > 0 && uint64_t(spec.tile_width) * uint64_t(std::max(spec.tile_height, 1)) * uint64_t(std::max(spec.tile_depth, 1)) * pixel_bytes >
                                   kMaxImageRowBytes)
      throw std::invalid_argument("image '" + name + "' has tiles of " + std::to_string(spec.tile_width) + " x " + std::to_string(spec.tile_height) +
                                  " pixels, more than the limit of " + std::to_string(kMaxImageRowBytes) + " bytes per tile");
    const int nc = spec.nchannels >= 3 ? 3 : 1;  // RGB, or grey broadcast (alpha and extra channels are not read)
    Bitmap bm;
    bm.width = spec.width;
    bm.height = spec.height;
    bm.source = path;
    bm.rgb.resize(size_t(count) * 3);
    std::vector<float> grey(nc == 1 ? size_t(count) : 0);
    float* pixels = nc == 3 ? bm.rgb.data() : grey.data();
    // Scanline files are read in at most 16 blocks, stopping at the first block that fails:
    // OpenImageIO's read_image goes on past a broken strip and appends one error per row (a 4 x 28532
    // TIFF with broken strip sizes took 25 s in the sanitizer build), and each read_scanlines call
    // that converts pixels takes a 64 MB buffer (90 ms each under ASan: 64-row blocks of a 4 x 65283
    // TIFF took 94 s). Both found by fuzz_heightfield.
    const int block_rows = spec.tile_width > 0 ? spec.height : std::max(64, (spec.height + 15) / 16);
    for (int y = 0; y < spec.height; y += block_rows) {
      const int y_end = std::min(spec.height, y + block_rows);
      float* block = pixels + size_t(y) * size_t(spec.width) * size_t(nc);
      const bool ok = spec.tile_width > 0 ? in->read_image(0, 0, 0, nc, OIIO::TypeDesc::FLOAT, block)
                                          : in->read_scanlines(0, 0, spec.y + y, spec.y + y_end, 0, 0, nc, OIIO::TypeDesc::FLOAT, block);
      if (!ok || in->has_error()) throw std::invalid_argument("cannot read image '" + name + "' (" + format + "): " + oiio_error(in->geterror()));
    }
    const bool integer_format = spec.format.basetype != OIIO::TypeDesc::FLOAT && spec.format.basetype != OIIO::TypeDesc::HALF &&
                                spec.format.basetype != OIIO::TypeDesc::DOUBLE;
    const std::string cs = spec.get_string_attribute("oiio:ColorSpace");
    const bool decode = !raw && integer_format && cs != "Linear" && cs != "linear";
    in->close();
    for (size_t i = 0; i < size_t(count); ++i)
      for (int c = 0; c < 3; ++c) {
        const float v = nc == 3 ? bm.rgb[3 * i + c] : grey[i];
        if (!std::isfinite(v))
          throw std::invalid_argument("image '" + name + "': pixel " + std::to_string(i % size_t(bm.width)) + ", " + std::to_string(i / size_t(bm.width)) +
                                      " (x, y) is not finite (" + std::to_string(v) + ")");
        bm.rgb[3 * i + c] = decode ? srgb_to_linear(v) : v;
      }
    return bm;
  } catch (const std::invalid_argument&) {
    throw;
  } catch (const std::bad_alloc&) {
    throw std::invalid_argument("cannot read image '" + name + "': out of memory");
  } catch (const std::exception& e) {
    throw std::invalid_argument("cannot read image '" + name + "' (" + format + "): " + printable(e.what(), 300));
  }
}

void write_image(const std::string& path, const Image& image) {
  const std::string ext = lower_extension(path);
  const bool hdr = ext == ".exr" || ext == ".hdr";
  auto out = OIIO::ImageOutput::create(path);
  if (!out) throw std::invalid_argument("cannot write '" + path + "': no image format for extension '" + ext + "'");
  OIIO::ImageSpec spec(image.width, image.height, 3, hdr ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::UINT8);
  if (!out->open(path, spec)) throw std::invalid_argument("cannot write '" + path + "': " + out->geterror());
  bool ok;
  if (hdr) {
    ok = out->write_image(OIIO::TypeDesc::FLOAT, image.rgb.data());
  } else {
    std::vector<uint8_t> bytes(image.rgb.size());
    for (size_t i = 0; i < bytes.size(); ++i) {
      const float v = std::isfinite(image.rgb[i]) ? std::clamp(image.rgb[i], 0.0f, 1.0f) : 0.0f;
      bytes[i] = uint8_t(std::lround(linear_to_srgb(v) * 255.0f));
    }
    ok = out->write_image(OIIO::TypeDesc::UINT8, bytes.data());
  }
  if (!ok || !out->close()) throw std::invalid_argument("cannot write '" + path + "': " + out->geterror());
}

}  // namespace limn
