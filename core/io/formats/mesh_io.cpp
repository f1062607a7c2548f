#include "core/io/formats/mesh_io.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <stdexcept>
#include "core/io/formats/files.h"

namespace limn {

namespace {

[[noreturn]] void fail(const std::string& name, const std::string& msg) {
  throw std::invalid_argument("mesh file '" + printable(name) + "': " + msg);
}

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }

// Whitespace-separated tokens of one line.
size_t split(std::string_view line, std::string_view* out, size_t max_tokens) {
  size_t n = 0, i = 0;
  while (i < line.size()) {
    while (i < line.size() && is_space(line[i])) ++i;
    if (i >= line.size()) break;
    const size_t b = i;
    while (i < line.size() && !is_space(line[i])) ++i;
    if (n < max_tokens) out[n] = line.substr(b, i - b);
    ++n;
  }
  return n;
}

// A number in the whole token (a leading '+' is allowed; no hexadecimal); false if it is not one or
// is out of the range of double.
bool parse_double(std::string_view t, double& v) {
  if (!t.empty() && t[0] == '+') t.remove_prefix(1);
  if (t.empty()) return false;
  const auto r = std::from_chars(t.data(), t.data() + t.size(), v, std::chars_format::general);
  return r.ec == std::errc() && r.ptr == t.data() + t.size();
}

bool parse_int(std::string_view t, int64_t& v) {
  if (!t.empty() && t[0] == '+') t.remove_prefix(1);
  if (t.empty()) return false;
  const auto r = std::from_chars(t.data(), t.data() + t.size(), v);
  if (r.ec == std::errc() && r.ptr == t.data() + t.size()) return true;
  double d;  // "3.0" for an integer
  if (!parse_double(t, d) || d != std::floor(d) || std::abs(d) > 9.0e15) return false;
  v = int64_t(d);
  return true;
}

std::string quote(std::string_view token) { return "'" + printable(token, 40) + "'"; }

// A coordinate as a float: finite and within float's range.
bool to_float(double d, float& f) {
  if (!std::isfinite(d) || std::abs(d) > double(std::numeric_limits<float>::max())) return false;
  f = float(d);
  return true;
}

// ---- PLY ------------------------------------------------------------------------------------------

enum class PlyType : uint8_t { I8, U8, I16, U16, I32, U32, F32, F64 };

std::optional<PlyType> ply_type(std::string_view s) {
  if (s == "char" || s == "int8") return PlyType::I8;
  if (s == "uchar" || s == "uint8") return PlyType::U8;
  if (s == "short" || s == "int16") return PlyType::I16;
  if (s == "ushort" || s == "uint16") return PlyType::U16;
  if (s == "int" || s == "int32") return PlyType::I32;
  if (s == "uint" || s == "uint32") return PlyType::U32;
  if (s == "float" || s == "float32") return PlyType::F32;
  if (s == "double" || s == "float64") return PlyType::F64;
  return std::nullopt;
}
size_t ply_size(PlyType t) {
  static const size_t sizes[] = {1, 1, 2, 2, 4, 4, 4, 8};
  return sizes[int(t)];
}
bool ply_integer(PlyType t) { return t < PlyType::F32; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::F32;        // the value type, or a list's item type
  bool list = false;
  PlyType count_type = PlyType::U8;   // a list's count type
  int role = -1;                      // vertex: 0..2 = x, y, z, 3..4 = texture u, v; face: 5 = the index list
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> props;
  size_t line = 0;
};

enum class PlyFormat { Ascii, BinaryLittle, BinaryBig };

class PlyReader {
 public:
  PlyReader(std::string_view bytes, const std::string& name) : m_bytes(bytes), m_name(name) {}

  MeshData read() {
    parse_header();
    assign_roles();
    check_sizes();
    if (m_format == PlyFormat::Ascii) read_elements<true>();
    else read_elements<false>();
    if (m_out.indices.empty()) fail(m_name, "contains no triangles");
    if (m_has_uv) {
      m_out.corner_uvs.reserve(m_out.indices.size() * 2);
      for (uint32_t i : m_out.indices) m_out.corner_uvs.insert(m_out.corner_uvs.end(), {m_uv[2 * size_t(i)], m_uv[2 * size_t(i) + 1]});
    }
    return std::move(m_out);
  }

 private:
  [[noreturn]] void header_error(const std::string& msg) const { fail(m_name, "header line " + std::to_string(m_line) + ": " + msg); }

  // The next header line (up to "\n", "\r\n" or "\r"); false at the end of the file.
  bool next_line(std::string_view& line) {
    if (m_pos >= m_bytes.size()) return false;
    const size_t e = m_bytes.find_first_of("\r\n", m_pos);
    if (e == std::string_view::npos) {
      line = m_bytes.substr(m_pos);
      m_pos = m_bytes.size();
    } else {
      line = m_bytes.substr(m_pos, e - m_pos);
      m_pos = e + ((m_bytes[e] == '\r' && e + 1 < m_bytes.size() && m_bytes[e + 1] == '\n') ? 2 : 1);
    }
    ++m_line;
    return true;
  }

  void parse_header() {
    std::string_view line, tok[6];
    if (!next_line(line) || split(line, tok, 6) != 1 || tok[0] != "ply") fail(m_name, "not a PLY file (the first line is not 'ply')");
    bool have_format = false;
    for (;;) {
      if (!next_line(line)) fail(m_name, "the header has no 'end_header' line (truncated?)");
      const size_t n = split(line, tok, 6);
      if (n == 0) continue;
      const std::string_view kw = tok[0];
      if (kw == "comment" || kw == "obj_info") continue;
      if (kw == "end_header") {
        if (n != 1) header_error("unexpected text after 'end_header'");
        break;
      }
      if (kw == "format") {
        if (have_format) header_error("a second 'format' line");
        if (n != 3) header_error("'format' needs a format and a version (e.g. 'format ascii 1.0')");
        if (tok[1] == "ascii") m_format = PlyFormat::Ascii;
        else if (tok[1] == "binary_little_endian") m_format = PlyFormat::BinaryLittle;
        else if (tok[1] == "binary_big_endian") m_format = PlyFormat::BinaryBig;
        else header_error("unknown format " + quote(tok[1]) + " (known: ascii, binary_little_endian, binary_big_endian)");
        if (tok[2] != "1.0") header_error("unsupported version " + quote(tok[2]) + " (known: 1.0)");
        have_format = true;
      } else if (kw == "element") {
        if (n != 3) header_error("'element' needs a name and a count");
        PlyElement e;
        e.name = std::string(tok[1]);
        e.line = m_line;
        const auto r = std::from_chars(tok[2].data(), tok[2].data() + tok[2].size(), e.count);
        if (r.ec != std::errc() || r.ptr != tok[2].data() + tok[2].size())
          header_error("the count of element " + quote(tok[1]) + " is not a number of at most 20 digits (" + quote(tok[2]) + ")");
        for (const PlyElement& o : m_elements)
          if (o.name == e.name) header_error("a second element " + quote(tok[1]));
        m_elements.push_back(std::move(e));
      } else if (kw == "property") {
        if (m_elements.empty()) header_error("'property' before any 'element'");
        PlyProperty p;
        if (n >= 2 && tok[1] == "list") {
          if (n != 5) header_error("'property list' needs a count type, an item type and a name");
          const auto ct = ply_type(tok[2]), it = ply_type(tok[3]);
          if (!ct || !ply_integer(*ct)) header_error("the count type of a list must be an integer type (got " + quote(tok[2]) + ")");
          if (!it) header_error("unknown type " + quote(tok[3]));
          p.list = true;
          p.count_type = *ct;
          p.type = *it;
          p.name = std::string(tok[4]);
        } else {
          if (n != 3) header_error("'property' needs a type and a name");
          const auto t = ply_type(tok[1]);
          if (!t) header_error("unknown type " + quote(tok[1]) + " (known: char, uchar, short, ushort, int, uint, float, double and int8 ... float64)");
          p.type = *t;
          p.name = std::string(tok[2]);
        }
        for (const PlyProperty& o : m_elements.back().props)
          if (o.name == p.name) header_error("a second property " + quote(p.name) + " in element " + quote(m_elements.back().name));
        m_elements.back().props.push_back(std::move(p));
      } else {
        header_error("unknown keyword " + quote(kw) + " (expected format, element, property, comment or end_header)");
      }
    }
    if (!have_format) fail(m_name, "the header has no 'format' line");
    m_data = m_pos;
  }

  void assign_roles() {
    PlyElement* vertex = nullptr;
    PlyElement* face = nullptr;
    for (PlyElement& e : m_elements) {
      if (e.name == "vertex") vertex = &e;
      if (e.name == "face") face = &e;
    }
    if (!vertex) fail(m_name, "the header declares no element 'vertex'");
    if (!face) fail(m_name, "the header declares no element 'face' (point clouds and triangle strips are not supported)");
    if (vertex->count > std::numeric_limits<uint32_t>::max())
      fail(m_name, "element 'vertex' declares " + std::to_string(vertex->count) + " vertices, more than 2^32 - 1");
    m_vertex_count = vertex->count;
    auto find = [](PlyElement& e, std::string_view name) -> PlyProperty* {
      for (PlyProperty& p : e.props)
        if (p.name == name) return &p;
      return nullptr;
    };
    const char* xyz[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k) {
      PlyProperty* p = find(*vertex, xyz[k]);
      if (!p) fail(m_name, std::string("element 'vertex' has no property '") + xyz[k] + "'");
      if (p->list) fail(m_name, std::string("property '") + xyz[k] + "' of element 'vertex' is a list, not a number");
      p->role = k;
    }
    static const char* uv_names[4][2] = {{"u", "v"}, {"s", "t"}, {"texture_u", "texture_v"}, {"texture_s", "texture_t"}};
    for (const auto& pair : uv_names) {
      PlyProperty *u = find(*vertex, pair[0]), *v = find(*vertex, pair[1]);
      if (u && v && !u->list && !v->list) {
        u->role = 3;
        v->role = 4;
        m_has_uv = true;
        break;
      }
    }
    PlyProperty* list = find(*face, "vertex_indices");
    if (!list) list = find(*face, "vertex_index");
    if (!list) fail(m_name, "element 'face' has no list 'vertex_indices' (or 'vertex_index')");
    if (!list->list) fail(m_name, "property '" + list->name + "' of element 'face' must be a list");
    if (!ply_integer(list->type)) fail(m_name, "the vertex indices of element 'face' must have an integer type");
    list->role = 5;
  }

  // Before anything is allocated: every element needs at least so many bytes (binary) or tokens
  // (ASCII); a count that the rest of the file cannot hold is refused here.
  void check_sizes() const {
    uint64_t remaining = m_bytes.size() - m_data;
    for (const PlyElement& e : m_elements) {
      if (e.props.empty() || e.count == 0) continue;
      uint64_t least = 0;  // bytes per instance (binary), or characters per instance (ASCII: a digit and a separator per value)
      for (const PlyProperty& p : e.props)
        least += m_format == PlyFormat::Ascii ? 2 : (p.list ? ply_size(p.count_type) : ply_size(p.type));
      if (e.count > (remaining + 1) / least)
        fail(m_name, "element '" + printable(e.name, 40) + "' (header line " + std::to_string(e.line) + ") declares " + std::to_string(e.count) +
                         " instances, but the " + std::to_string(m_bytes.size() - m_data) + " bytes after the header cannot hold them (truncated file or wrong count?)");
      remaining -= std::min(remaining, e.count * least);
    }
  }

  // ---- values ----
  // One value of type t of instance i of element e; `what()` describes it for an error message.
  template <bool Ascii, class What>
  double value(PlyType t, const PlyElement& e, uint64_t i, const What& what) {
    if constexpr (Ascii) {
      const std::string_view tok = next_token(e, i);
      if (ply_integer(t)) {
        int64_t v;
        if (!parse_int(tok, v)) fail(m_name, "line " + std::to_string(m_line) + ": " + quote(tok) + " is not an integer (" + what() + " of " + printable(e.name, 40) + " " + std::to_string(i) + ")");
        return double(v);
      }
      double v;
      if (!parse_double(tok, v)) fail(m_name, "line " + std::to_string(m_line) + ": " + quote(tok) + " is not a number (" + what() + " of " + printable(e.name, 40) + " " + std::to_string(i) + ")");
      return v;
    } else {
      const size_t n = ply_size(t);
      if (m_bytes.size() - m_pos < n)
        fail(m_name, "the file ends inside " + printable(e.name, 40) + " " + std::to_string(i) + " of " + std::to_string(e.count) + " (truncated?)");
      unsigned char b[8];
      std::memcpy(b, m_bytes.data() + m_pos, n);
      m_pos += n;
      if (m_format == PlyFormat::BinaryBig) std::reverse(b, b + n);
      switch (t) {
        case PlyType::I8: { int8_t v; std::memcpy(&v, b, 1); return v; }
        case PlyType::U8: return b[0];
        case PlyType::I16: { int16_t v; std::memcpy(&v, b, 2); return v; }
        case PlyType::U16: { uint16_t v; std::memcpy(&v, b, 2); return v; }
        case PlyType::I32: { int32_t v; std::memcpy(&v, b, 4); return v; }
        case PlyType::U32: { uint32_t v; std::memcpy(&v, b, 4); return v; }
        case PlyType::F32: { float v; std::memcpy(&v, b, 4); return v; }
        case PlyType::F64: { double v; std::memcpy(&v, b, 8); return v; }
      }
      return 0.0;
    }
  }

  std::string_view next_token(const PlyElement& e, uint64_t i) {
    while (m_pos < m_bytes.size() && is_space(m_bytes[m_pos])) {
      if (m_bytes[m_pos] == '\n') ++m_line;
      ++m_pos;
    }
    if (m_pos >= m_bytes.size())
      fail(m_name, "line " + std::to_string(m_line) + ": the file ends inside " + printable(e.name, 40) + " " + std::to_string(i) + " of " +
                       std::to_string(e.count) + " (truncated?)");
    const size_t b = m_pos;
    while (m_pos < m_bytes.size() && !is_space(m_bytes[m_pos])) ++m_pos;
    return m_bytes.substr(b, m_pos - b);
  }

  template <bool Ascii>
  void read_elements() {
    m_pos = m_data;
    if (Ascii) ++m_line;  // the data starts on the line after end_header
    m_out.positions.reserve(size_t(m_vertex_count) * 3);
    if (m_has_uv) m_uv.reserve(size_t(m_vertex_count) * 2);
    std::vector<uint32_t> polygon;
    for (const PlyElement& e : m_elements) {
      if (e.props.empty()) continue;
      const bool is_vertex = e.name == "vertex";
      for (uint64_t i = 0; i < e.count; ++i) {
        float xyzuv[5] = {0, 0, 0, 0, 0};
        for (const PlyProperty& p : e.props) {
          if (!p.list) {
            const double v = value<Ascii>(p.type, e, i, [&] { return "property '" + printable(p.name, 40) + "'"; });
            if (is_vertex && p.role >= 0 && !to_float(v, xyzuv[p.role]))
              fail(m_name, where<Ascii>() + "vertex " + std::to_string(i) + ": " + printable(p.name, 40) + " = " + number_text(v) + " is not a finite float");
            continue;
          }
          const double c = value<Ascii>(p.count_type, e, i, [&] { return "the count of list '" + printable(p.name, 40) + "'"; });
          if (c < 0) fail(m_name, where<Ascii>() + printable(e.name, 40) + " " + std::to_string(i) + ": list '" + printable(p.name, 40) + "' has a negative count (" + number_text(c) + ")");
          const uint64_t n = uint64_t(c);
          if (!Ascii && n > (m_bytes.size() - m_pos) / ply_size(p.type))
            fail(m_name, e.name + " " + std::to_string(i) + ": list '" + printable(p.name, 40) + "' declares " + std::to_string(n) +
                             " items, more than the rest of the file holds (truncated file or wrong count?)");
          if (p.role != 5) {  // another list: skipped by its declared types
            if (Ascii)
              for (uint64_t k = 0; k < n; ++k) value<Ascii>(p.type, e, i, [&] { return "item " + std::to_string(k) + " of list '" + printable(p.name, 40) + "'"; });
            else
              m_pos += size_t(n * ply_size(p.type));
            continue;
          }
          if (n < 3) fail(m_name, where<Ascii>() + "face " + std::to_string(i) + " has " + std::to_string(n) + " vertices (a face needs at least 3)");
          polygon.clear();
          for (uint64_t k = 0; k < n; ++k) {
            const double v = value<Ascii>(p.type, e, i, [&] { return "vertex index " + std::to_string(k); });
            if (!(v >= 0.0 && v < double(m_vertex_count)))
              fail(m_name, where<Ascii>() + "face " + std::to_string(i) + " refers to vertex " + number_text(v) + ", but there are " +
                               std::to_string(m_vertex_count) + " vertices");
            polygon.push_back(uint32_t(v));
          }
          for (size_t k = 1; k + 1 < polygon.size(); ++k) m_out.indices.insert(m_out.indices.end(), {polygon[0], polygon[k], polygon[k + 1]});
        }
        if (is_vertex) {
          m_out.positions.insert(m_out.positions.end(), xyzuv, xyzuv + 3);
          if (m_has_uv) m_uv.insert(m_uv.end(), xyzuv + 3, xyzuv + 5);
        }
      }
    }
    if (Ascii) {
      while (m_pos < m_bytes.size() && is_space(m_bytes[m_pos])) {
        if (m_bytes[m_pos] == '\n') ++m_line;
        ++m_pos;
      }
      if (m_pos < m_bytes.size()) fail(m_name, "line " + std::to_string(m_line) + ": unexpected data after the last element");
    } else {
      for (size_t k = m_pos; k < m_bytes.size(); ++k)
        if (!is_space(m_bytes[k]) && m_bytes[k] != '\0')
          fail(m_name, std::to_string(m_bytes.size() - m_pos) + " bytes of unexpected data after the last element (wrong counts?)");
    }
  }

  template <bool Ascii>
  std::string where() const {
    return Ascii ? "line " + std::to_string(m_line) + ": " : std::string();
  }

  std::string_view m_bytes;
  const std::string& m_name;
  size_t m_pos = 0, m_line = 0, m_data = 0;
  PlyFormat m_format = PlyFormat::Ascii;
  std::vector<PlyElement> m_elements;
  uint64_t m_vertex_count = 0;
  bool m_has_uv = false;
  std::vector<float> m_uv;
  MeshData m_out;
};

}  // namespace

MeshData read_ply(std::string_view bytes, const std::string& name) { return PlyReader(bytes, name).read(); }

// ---- OBJ ------------------------------------------------------------------------------------------

MeshData read_obj(std::string_view bytes, const std::string& name) {
  std::vector<float> v, vt;           // every v and vt of the file
  std::vector<uint32_t> remap;        // file vertex -> output vertex (first use by a face), or ~0
  MeshData out;
  bool all_uv = true;
  std::vector<uint32_t> polygon;
  std::vector<float> polygon_uv;
  std::string_view tok[8];
  size_t pos = 0, line_no = 0;
  while (pos < bytes.size()) {
    size_t e = bytes.find('\n', pos);
    if (e == std::string_view::npos) e = bytes.size();
    std::string_view line = bytes.substr(pos, e - pos);
    pos = e + 1;
    ++line_no;
    if (line.find('\0') != std::string_view::npos) fail(name, "line " + std::to_string(line_no) + ": binary data (not an OBJ file)");
    if (const size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    const size_t n = split(line, tok, 8);
    if (n == 0) continue;
    const auto at = [line_no] { return "line " + std::to_string(line_no) + ": "; };
    if (tok[0] == "v") {
      if (n < 4) fail(name, at() + "a vertex needs 3 coordinates");
      for (int k = 1; k <= 3; ++k) {
        double d;
        float f;
        if (!parse_double(tok[k], d)) fail(name, at() + quote(tok[k]) + " is not a number (vertex " + std::to_string(v.size() / 3 + 1) + ")");
        if (!to_float(d, f))
          fail(name, at() + "vertex " + std::to_string(v.size() / 3 + 1) + ": coordinate " + number_text(d) + " is not a finite float");
        v.push_back(f);
      }
      if (v.size() / 3 > std::numeric_limits<uint32_t>::max()) fail(name, at() + "more than 2^32 - 1 vertices");
    } else if (tok[0] == "vt") {
      if (n < 2) fail(name, at() + "a texture coordinate needs at least u");
      for (int k = 1; k <= 2; ++k) {
        double d = 0.0;
        float f;
        if (k < int(n) && !parse_double(tok[k], d)) fail(name, at() + quote(tok[k]) + " is not a number (texture coordinate " + std::to_string(vt.size() / 2 + 1) + ")");
        if (!to_float(d, f)) fail(name, at() + "texture coordinate " + std::to_string(vt.size() / 2 + 1) + ": " + number_text(d) + " is not a finite float");
        vt.push_back(f);
      }
    } else if (tok[0] == "f") {
      if (n < 4) fail(name, at() + "a face needs at least 3 vertices (got " + std::to_string(n - 1) + ")");
      polygon.clear();
      polygon_uv.clear();
      int with_uv = 0;
      // Corners: re-split the line, since a polygon may have more than the 7 corners `tok` holds.
      size_t i = 0, corners = 0;
      bool first = true;
      while (i < line.size()) {
        while (i < line.size() && is_space(line[i])) ++i;
        if (i >= line.size()) break;
        const size_t b = i;
        while (i < line.size() && !is_space(line[i])) ++i;
        const std::string_view corner = line.substr(b, i - b);
        if (first) {  // the keyword
          first = false;
          continue;
        }
        ++corners;
        const size_t s1 = corner.find('/');
        const std::string_view vs = corner.substr(0, s1);
        std::string_view ts;
        if (s1 != std::string_view::npos) {
          const size_t s2 = corner.find('/', s1 + 1);
          ts = corner.substr(s1 + 1, s2 == std::string_view::npos ? std::string_view::npos : s2 - s1 - 1);
        }
        auto resolve = [&](std::string_view t, size_t count, const char* what, const char* plural) -> size_t {
          int64_t k;
          if (!parse_int(t, k) || k == 0)
            fail(name, at() + "corner " + quote(corner) + ": " + quote(t) + " is not a " + what + " number (1-based, or negative to count back)");
          const int64_t idx = k > 0 ? k - 1 : int64_t(count) + k;
          if (idx < 0 || idx >= int64_t(count))
            fail(name, at() + "corner " + quote(corner) + " refers to " + what + " " + std::to_string(k) + ", but " + std::to_string(count) + " " +
                           (count == 1 ? std::string(what) + " is" : std::string(plural) + " are") + " defined before this line");
          return size_t(idx);
        };
        const size_t vi = resolve(vs, v.size() / 3, "vertex", "vertices");
        if (remap.size() < v.size() / 3) remap.resize(v.size() / 3, ~0u);
        if (remap[vi] == ~0u) {
          remap[vi] = uint32_t(out.positions.size() / 3);
          out.positions.insert(out.positions.end(), {v[3 * vi], v[3 * vi + 1], v[3 * vi + 2]});
        }
        polygon.push_back(remap[vi]);
        if (!ts.empty()) {
          const size_t ti = resolve(ts, vt.size() / 2, "texture coordinate", "texture coordinates");
          polygon_uv.insert(polygon_uv.end(), {vt[2 * ti], vt[2 * ti + 1]});
          ++with_uv;
        }
      }
      if (with_uv != 0 && size_t(with_uv) != corners)
        fail(name, at() + "some corners of this face have texture coordinates and some do not");
      if (with_uv == 0) all_uv = false;
      for (size_t k = 1; k + 1 < polygon.size(); ++k) {
        out.indices.insert(out.indices.end(), {polygon[0], polygon[k], polygon[k + 1]});
        if (with_uv)
          for (size_t c : {size_t(0), k, k + 1}) out.corner_uvs.insert(out.corner_uvs.end(), {polygon_uv[2 * c], polygon_uv[2 * c + 1]});
      }
      if (out.indices.size() / 3 > std::numeric_limits<uint32_t>::max() / 3) fail(name, at() + "too many triangles");
    }
    // vn, vp, g, o, s, usemtl, mtllib, l, p and the free-form geometry statements are ignored.
  }
  if (out.indices.empty()) fail(name, "contains no triangles (no 'f' lines)");
  if (!all_uv) out.corner_uvs.clear();  // a file where only some faces have uvs: drop them rather than misalign them
  return out;
}

MeshData read_mesh_file(const std::string& path) {
  const std::string bytes = read_file_bytes(path, "mesh file", kMaxMeshFileBytes);
  const bool ply_magic = bytes.size() >= 4 && bytes.compare(0, 3, "ply") == 0 && (bytes[3] == '\n' || bytes[3] == '\r');
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ply_magic || ext == ".ply") return read_ply(bytes, path);
  return read_obj(bytes, path);
}

void write_ply(const std::string& path, const std::vector<float>& positions, const std::vector<uint32_t>& indices) {
  std::ofstream f(path, std::ios::binary);
  if (!f) throw std::invalid_argument("cannot write '" + path + "'");
  f << "ply\nformat binary_little_endian 1.0\ncomment written by limn\n"
    << "element vertex " << positions.size() / 3 << "\nproperty float x\nproperty float y\nproperty float z\n"
    << "element face " << indices.size() / 3 << "\nproperty list uchar int vertex_indices\nend_header\n";
  f.write(reinterpret_cast<const char*>(positions.data()), std::streamsize(positions.size() * sizeof(float)));
  for (size_t t = 0; t < indices.size(); t += 3) {
    const uint8_t n = 3;
    f.write(reinterpret_cast<const char*>(&n), 1);
    const int32_t tri[3] = {int32_t(indices[t]), int32_t(indices[t + 1]), int32_t(indices[t + 2])};
    f.write(reinterpret_cast<const char*>(tri), sizeof(tri));
  }
  if (!f) throw std::invalid_argument("cannot write '" + path + "'");
}

}  // namespace limn
