#include "core/io/formats/image_io.h"

#include <OpenImageIO/imageio.h>
#include <algorithm>
#include <filesystem>
#include <stdexcept>

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

Bitmap read_image(const std::string& path, bool raw) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw std::invalid_argument("image file '" + path + "' not found");
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw std::invalid_argument("cannot read image '" + path + "': " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
    throw std::invalid_argument("image '" + path + "' is empty");
  std::vector<float> pixels(size_t(spec.width) * spec.height * spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, pixels.data()))
    throw std::invalid_argument("cannot read image '" + path + "': " + in->geterror());
  const bool integer_format = spec.format.basetype != OIIO::TypeDesc::FLOAT && spec.format.basetype != OIIO::TypeDesc::HALF &&
                              spec.format.basetype != OIIO::TypeDesc::DOUBLE;
  const std::string cs = spec.get_string_attribute("oiio:ColorSpace");
  const bool decode = !raw && integer_format && cs != "Linear" && cs != "linear";
  in->close();

  Bitmap bm;
  bm.width = spec.width;
  bm.height = spec.height;
  bm.source = path;
  bm.rgb.resize(size_t(bm.width) * bm.height * 3);
  const int nc = spec.nchannels;
  for (size_t i = 0; i < size_t(bm.width) * bm.height; ++i)
    for (int c = 0; c < 3; ++c) {
      float v = pixels[i * nc + (nc >= 3 ? c : 0)];
      if (!std::isfinite(v)) throw std::invalid_argument("image '" + path + "': pixel " + std::to_string(i) + " is not finite");
      bm.rgb[3 * i + c] = decode ? srgb_to_linear(v) : v;
    }
  return bm;
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
