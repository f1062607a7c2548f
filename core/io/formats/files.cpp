#include "core/io/formats/files.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace limn {

uint64_t check_regular_file(const std::string& path, const std::string& what) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);  // follows symbolic links; opens nothing
  if (ec || st.type() == fs::file_type::not_found || st.type() == fs::file_type::none)
    throw std::invalid_argument(what + " '" + printable(path) + "' not found");
  if (st.type() == fs::file_type::directory) throw std::invalid_argument(what + " '" + printable(path) + "' is a directory, not a file");
  if (st.type() != fs::file_type::regular)
    throw std::invalid_argument(what + " '" + printable(path) + "' is not a regular file (a FIFO, socket or device)");
  const uintmax_t size = fs::file_size(path, ec);
  if (ec) throw std::invalid_argument("cannot read " + what + " '" + printable(path) + "': " + ec.message());
  return uint64_t(size);
}

std::string read_file_bytes(const std::string& path, const std::string& what, uint64_t max_bytes) {
  const uint64_t size = check_regular_file(path, what);
  if (size > max_bytes)
    throw std::invalid_argument(what + " '" + printable(path) + "' is " + std::to_string(size) + " bytes, more than the limit of " +
                                std::to_string(max_bytes));
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::invalid_argument("cannot open " + what + " '" + printable(path) + "'");
  std::string bytes(size_t(size), '\0');
  f.read(bytes.data(), std::streamsize(size));
  bytes.resize(size_t(f.gcount()));  // the file may have shrunk meanwhile
  if (f.bad()) throw std::invalid_argument("cannot read " + what + " '" + printable(path) + "'");
  return bytes;
}

namespace {
// Length of the valid UTF-8 sequence starting at s[i] (0 if invalid): no overlong forms, no
// surrogates, nothing above U+10FFFF.
size_t utf8_length(std::string_view s, size_t i) {
  const auto b = [&](size_t k) { return uint8_t(s[i + k]); };
  const uint8_t c = b(0);
  if (c < 0x80) return 1;
  size_t n;
  uint32_t cp;
  if (c >= 0xC2 && c <= 0xDF) n = 2, cp = c & 0x1F;
  else if (c >= 0xE0 && c <= 0xEF) n = 3, cp = c & 0x0F;
  else if (c >= 0xF0 && c <= 0xF4) n = 4, cp = c & 0x07;
  else return 0;
  if (i + n > s.size()) return 0;
  for (size_t k = 1; k < n; ++k) {
    if ((b(k) & 0xC0) != 0x80) return 0;
    cp = (cp << 6) | (b(k) & 0x3F);
  }
  if ((n == 3 && cp < 0x800) || (n == 4 && (cp < 0x10000 || cp > 0x10FFFF)) || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
  return n;
}
}  // namespace

std::string printable(std::string_view text, size_t max_chars) {
  std::string out;
  size_t chars = 0;
  for (size_t i = 0; i < text.size();) {
    if (chars >= max_chars) {
      out += "...";
      break;
    }
    const size_t n = utf8_length(text, i);
    const uint8_t c = uint8_t(text[i]);
    if (n == 0 || (n == 1 && (c < 0x20 || c == 0x7F))) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02X", c);
      out += buf;
      i += 1;
    } else {
      out.append(text.substr(i, n));
      i += n;
    }
    ++chars;
  }
  return out;
}

bool valid_utf8(std::string_view text) {
  for (size_t i = 0; i < text.size();) {
    const size_t n = utf8_length(text, i);
    if (n == 0) return false;
    i += n;
  }
  return true;
}

TextPosition text_position(std::string_view text, size_t offset) {
  TextPosition p;
  const size_t end = std::min(offset, text.size());
  for (size_t i = 0; i < end; ++i) {
    if (text[i] == '\n') {
      ++p.line;
      p.column = 1;
    } else {
      ++p.column;
    }
  }
  return p;
}

std::string number_text(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

std::string number_text(float v) {
  if (std::isnan(v) || std::isinf(v)) return number_text(double(v));
  char buf[64];
  auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

}  // namespace limn
