#include "core/io/scene/props.h"

#include <algorithm>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include "core/io/formats/files.h"
#include "core/io/formats/image_io.h"
#include "core/io/scene/shapes.h"

namespace limn::io_detail {

std::string str_field(const json& j, const char* key, const std::string& def) {
  if (!j.is_object()) return def;
  auto it = j.find(key);
  return it != j.end() && it->is_string() ? it->get<std::string>() : def;
}

const std::map<std::string, Category>& known_types() {
  static const std::map<std::string, Category> table = [] {
    std::map<std::string, Category> t = {
        {"scene", Category::Scene},          {"perspective", Category::Sensor},    {"hdrfilm", Category::Film},
        {"independent", Category::Sampler},  {"stratified", Category::Sampler},    {"multijitter", Category::Sampler},
        {"box", Category::Filter},           {"gaussian", Category::Filter},       {"tent", Category::Filter},
        {"path", Category::Integrator},      {"direct", Category::Integrator},     {"diffuse", Category::Bsdf},
        {"conductor", Category::Bsdf},       {"roughconductor", Category::Bsdf},   {"dielectric", Category::Bsdf},
        {"roughdielectric", Category::Bsdf}, {"twosided", Category::Bsdf},         {"area", Category::Emitter},
        {"point", Category::Emitter},        {"directional", Category::Emitter},   {"constant", Category::Emitter},
        {"envmap", Category::Emitter},       {"bitmap", Category::Texture},        {"ref", Category::Ref},
        {"rgb", Category::Texture},          {"spot", Category::Emitter}};
    for (const auto& [name, kind] : shape_kinds())
      if (!t.emplace(name, Category::Shape).second) throw std::logic_error("shape kind '" + name + "' is already a known type");
    return t;
  }();
  return table;
}

std::string known_of(Category c) {
  std::string out;
  for (const auto& [name, cat] : known_types())
    if (cat == c && name != "rgb") out += (out.empty() ? "" : ", ") + name;
  return out;
}

float Props::number(const std::string& k) const {
  if (!has(k)) fail("missing parameter '" + k + "'");
  const json& v = raw(k);
  if (!v.is_number()) fail("'" + k + "' must be a number (got " + brief(v) + ")");
  const double d = v.get<double>();
  if (!std::isfinite(d) || !std::isfinite(float(d)) || std::abs(d) > 3.0e38)
    fail("'" + k + "' must be a finite float (got " + brief(v) + ")");
  return float(d);
}

int Props::integer(const std::string& k, int def) const {
  if (!has(k)) return def;
  const json& v = raw(k);
  if (!v.is_number_integer()) fail("'" + k + "' must be an integer (got " + brief(v) + ")");
  const int64_t i = v.get<int64_t>();
  if (i < -(int64_t(1) << 30) || i > (int64_t(1) << 30)) fail("'" + k + "' is out of range (got " + brief(v) + ")");
  return int(i);
}

bool Props::boolean(const std::string& k, bool def) const {
  if (!has(k)) return def;
  const json& v = raw(k);
  if (!v.is_boolean()) fail("'" + k + "' must be true or false (got " + brief(v) + ")");
  return v.get<bool>();
}

std::string Props::string(const std::string& k, const std::string& def) const {
  if (!has(k)) return def;
  const json& v = raw(k);
  if (!v.is_string()) fail("'" + k + "' must be a string (got " + brief(v) + ")");
  return v.get<std::string>();
}

std::string Props::required_string(const std::string& k) const {
  if (!has(k)) fail("missing parameter '" + k + "'");
  return string(k, "");
}

std::string Props::file(const std::string& k) const {
  const std::string name = required_string(k);
  if (name.empty()) fail("'" + k + "' is an empty file name");
  if (name.find('\0') != std::string::npos) fail("'" + k + "' contains a NUL character (" + brief(raw(k)) + ")");
  std::filesystem::path p(name);
  if (p.is_relative()) p = m_ctx.base_dir / p;
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(p, ec);  // opens nothing (a FIFO would block)
  if (ec || !std::filesystem::exists(st))
    fail("'" + k + "': file '" + printable(name) + "' not found (looked for " + printable(p.string()) + ")");
  if (std::filesystem::is_directory(st)) fail("'" + k + "': '" + printable(name) + "' is a directory, not a file");
  if (!std::filesystem::is_regular_file(st)) fail("'" + k + "': '" + printable(name) + "' is not a regular file (a FIFO, socket or device)");
  return p.string();
}

std::vector<double> Props::numbers(const json& v, const std::string& k, size_t n) const {
  if (v.is_object() && v.contains("__limn_array__")) {
    const ArrayData& a = array_ref(v, k);
    if (a.values.size() != n) fail("'" + k + "' must have " + std::to_string(n) + " values (got " + std::to_string(a.values.size()) + ")");
    for (double d : a.values)
      if (!(std::abs(d) <= 3.0e38)) fail("'" + k + "' has an entry that is not a finite float (" + number_text(d) + ")");
    return a.values;
  }
  if (!v.is_array() || v.size() != n) fail("'" + k + "' must be a list of " + std::to_string(n) + " numbers (got " + brief(v) + ")");
  std::vector<double> out;
  for (const json& e : v) {
    if (!e.is_number() || !(std::abs(e.get<double>()) <= 3.0e38)) fail("'" + k + "' must contain finite float numbers (got " + brief(v) + ")");
    out.push_back(e.get<double>());
  }
  return out;
}

Vec3 Props::vec3(const std::string& k, const Vec3& def) const {
  if (!has(k)) return def;
  const auto v = numbers(raw(k), k, 3);
  return Vec3(float(v[0]), float(v[1]), float(v[2]));
}

Spectrum Props::spectrum(const std::string& k, const Spectrum& def) const {
  if (!has(k)) return def;
  return spectrum_value(raw(k), k);
}

Spectrum Props::spectrum_value(const json& v0, const std::string& k) const {
  const json* v = &v0;
  if (v->is_object() && str_field(*v, "type", "") == "rgb") {
    if (!v->contains("value")) fail("'" + k + "': rgb needs a 'value'");
    v = &v->at("value");
  }
  Spectrum s;
  if (v->is_number()) s = Spectrum(v->get<float>());
  else if (v->is_object() && v->contains("type")) fail("'" + k + "' must be a colour (number, [r, g, b] or rgb), not " + brief(*v));
  else {
    const auto n = numbers(*v, k, 3);
    s = Spectrum(float(n[0]), float(n[1]), float(n[2]));
  }
  if (!is_finite(s) || s.x < 0.0f || s.y < 0.0f || s.z < 0.0f) fail("'" + k + "' must be finite and >= 0 (got " + brief(*v) + ")");
  return s;
}

Texture Props::texture(const std::string& k, const Spectrum& def) const {
  Texture t;
  t.value = def;
  if (!has(k)) return t;
  const json& v = raw(k);
  if (v.is_object() && str_field(v, "type", "") == "bitmap") {
    Props bp(m_ctx, v, m_what + ": texture '" + k + "' (bitmap)");
    const std::string path = bp.file("filename");
    try {
      t.bitmap = std::make_shared<Bitmap>(read_image(path, bp.boolean("raw", false)));
    } catch (const std::invalid_argument& e) {
      bp.fail(std::string("'filename': ") + e.what());
    }
    bp.check_unused();
    return t;
  }
  t.value = spectrum_value(v, k);
  return t;
}

std::string Props::brief(const json& v) const {
  if (v.is_object() && v.size() == 1 && v.contains("__limn_array__")) {
    const json& idx = v.at("__limn_array__");
    if (m_ctx.arrays && idx.is_number_integer() && idx.get<size_t>() < m_ctx.arrays->size()) {
      std::string shape;
      for (size_t d : (*m_ctx.arrays)[idx.get<size_t>()].shape) shape += (shape.empty() ? "" : ", ") + std::to_string(d);
      return "an array of shape (" + shape + (m_ctx.arrays->at(idx.get<size_t>()).shape.size() == 1 ? ",)" : ")");
    }
  }
  return io_detail::brief(v);
}

const ArrayData& Props::array_ref(const json& v, const std::string& k) const {
  const json& idx = v.at("__limn_array__");
  if (!m_ctx.arrays || !idx.is_number_integer() || idx.get<size_t>() >= m_ctx.arrays->size())
    fail("'" + k + "' refers to an array that was not passed");
  return (*m_ctx.arrays)[idx.get<size_t>()];
}

ArrayData Props::array(const std::string& k) const {
  if (!has(k)) fail("missing parameter '" + k + "'");
  const json& v = raw(k);
  if (v.is_object() && v.contains("__limn_array__")) return array_ref(v, k);
  if (!v.is_array()) fail("'" + k + "' must be an array (nested lists of numbers), got " + brief(v));
  ArrayData a;
  // Every number must sit at the same depth, under lists of equal lengths per depth: [[0, 0], [[0], [0]]]
  // is ragged, not an array of shape (2, 2, 1).
  size_t leaf_depth = SIZE_MAX;
  std::function<void(const json&, size_t)> walk = [&](const json& e, size_t depth) {
    if (e.is_array()) {
      if (depth >= leaf_depth) fail("'" + k + "' is a ragged array (a list where numbers were expected, at depth " + std::to_string(depth) + ")");
      if (a.shape.size() <= depth) a.shape.push_back(e.size());
      else if (a.shape[depth] != e.size()) fail("'" + k + "' is a ragged array (lists of lengths " + std::to_string(a.shape[depth]) + " and " +
                                                  std::to_string(e.size()) + " at depth " + std::to_string(depth) + ")");
      for (const json& x : e) walk(x, depth + 1);
    } else if (e.is_number()) {
      if (leaf_depth == SIZE_MAX) leaf_depth = depth;
      if (depth != leaf_depth || depth != a.shape.size()) fail("'" + k + "' is a ragged array (numbers at different depths)");
      a.values.push_back(e.get<double>());
      a.integer = a.values.size() == 1 ? e.is_number_integer() : a.integer && e.is_number_integer();
    } else {
      fail("'" + k + "' must be an array of numbers (got " + brief(e) + " in it)");
    }
  };
  walk(v, 0);
  size_t count = 1;
  for (size_t n : a.shape) count *= n;
  if (a.shape.empty() || count != a.values.size()) fail("'" + k + "' is a ragged array or not an array (got " + brief(v) + ")");
  return a;
}

Transform Props::transform(const std::string& k) const {
  if (!has(k)) return Transform();
  Transform t;
  try {
    t = parse_transform(raw(k), k);
  } catch (const std::invalid_argument& e) {
    if (std::string(e.what()).rfind(m_ctx.source, 0) == 0) throw;
    fail("'" + k + "': " + e.what());
  }
  check_transform(t, k);
  return t;
}

void Props::check_transform(const Transform& t, const std::string& k) const {
  const Mat4d& m = t.matrix();
  const Mat4d& inv = t.inverse_matrix();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      if (!std::isfinite(m[c][r]))
        fail("'" + k + "' overflows: its matrix entry at row " + std::to_string(r) + ", column " + std::to_string(c) + " is " + number_text(m[c][r]) +
             " (the steps multiply to values beyond double)");
      if (!std::isfinite(inv[c][r]))
        fail("'" + k + "' cannot be inverted in double precision (its inverse has the entry " + number_text(inv[c][r]) + "; it scales by about " +
             number_text(norm(Vec3d(m[0]))) + ")");
    }
  if (std::abs(m[0][3]) > 1e-9 || std::abs(m[1][3]) > 1e-9 || std::abs(m[2][3]) > 1e-9 || std::abs(m[3][3] - 1.0) > 1e-9)
    fail("'" + k + "' must be affine: its last row must be [0, 0, 0, 1] (got [" + number_text(m[0][3]) + ", " + number_text(m[1][3]) + ", " +
         number_text(m[2][3]) + ", " + number_text(m[3][3]) + "])");
  // Singular or nearly so, independently of the scale: the determinant of the unit columns.
  const double n0 = norm(Vec3d(m[0])), n1 = norm(Vec3d(m[1])), n2 = norm(Vec3d(m[2]));
  const double d = (n0 > 0.0 && n1 > 0.0 && n2 > 0.0) ? glm::dot(Vec3d(m[0]) / n0, glm::cross(Vec3d(m[1]) / n1, Vec3d(m[2]) / n2)) : 0.0;
  if (!(std::abs(d) > 1e-12))
    fail("'" + k + "' is singular (it maps space onto a plane, a line or a point; its columns have lengths " + number_text(n0) + ", " +
         number_text(n1) + ", " + number_text(n2) + ")");
}

std::vector<std::pair<std::string, const json*>> Props::children() const {
  std::vector<std::pair<std::string, const json*>> out;
  for (auto it = m_j.begin(); it != m_j.end(); ++it)
    if (it.value().is_object() && it.value().contains("type") && it.value().at("type").is_string() && !m_used.count(it.key())) {
      out.emplace_back(it.key(), &it.value());
    }
  return out;
}

void Props::check_unused() const {
  size_t unused = 0;
  for (auto it = m_j.begin(); it != m_j.end(); ++it)
    if (!m_used.count(it.key()) && ++unused <= 20)
      m_ctx.scene->warnings.push_back(m_ctx.source + ": " + m_what + ": unused parameter '" + printable(it.key(), 60) + "'");
  if (unused > 20)
    m_ctx.scene->warnings.push_back(m_ctx.source + ": " + m_what + ": and " + std::to_string(unused - 20) + " more unused parameters");
}

Transform Props::parse_transform(const json& v, const std::string& k) const {
  auto matrix = [&](const json& m) {
    if (m.is_object() && m.contains("__limn_array__")) {
      const ArrayData& a = array_ref(m, k);
      if (a.shape != std::vector<size_t>{4, 4}) fail("'" + k + "' matrix must have shape (4, 4) (got " + shape_text(a.shape) + ")");
      Mat4d out;
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) out[c][r] = a.values[size_t(r) * 4 + c];
      return Transform(out);
    }
    if (!m.is_array() || m.size() != 4) fail("'" + k + "' matrix must be a list of 4 rows of 4 numbers (got " + brief(m) + ")");
    Mat4d out;
    for (int r = 0; r < 4; ++r) {
      const auto row = numbers(m[r], k, 4);
      for (int c = 0; c < 4; ++c) out[c][r] = row[c];
    }
    return Transform(out);
  };
  auto vec3d = [&](const json& e) {
    const auto n = numbers(e, k, 3);
    return Vec3d(n[0], n[1], n[2]);
  };
  if (v.is_array() && !v.empty() && v[0].is_array()) return matrix(v);
  if (v.is_object() && v.contains("__limn_array__")) return matrix(v);
  if (v.is_array()) {
    Transform t;
    for (const json& step : v) t = parse_transform(step, k) * t;  // first in the list is applied first
    return t;
  }
  if (!v.is_object() || v.size() != 1)
    fail("'" + k + "' must be a 4x4 matrix, one of {translate, scale, rotate, look_at, matrix}, or a list of them (got " + brief(v) + ")");
  // The one key and its value (not a structured binding to *v.items().begin(): the proxy it
  // refers to dies at the end of that statement; AddressSanitizer found the dangling read).
  const auto step = v.begin();
  const std::string op = step.key();
  const json& arg = step.value();
  if (op == "translate") return Transform::translate(vec3d(arg));
  if (op == "scale") return Transform::scale(arg.is_number() ? Vec3d(arg.get<double>()) : vec3d(arg));
  if (op == "matrix") return matrix(arg);
  auto only_keys = [&](const char* what, std::initializer_list<const char*> known) {
    for (auto it = arg.begin(); it != arg.end(); ++it)
      if (std::none_of(known.begin(), known.end(), [&](const char* n) { return it.key() == n; }))
        fail("'" + k + "': unknown key '" + printable(it.key(), 40) + "' in " + what);
  };
  if (op == "rotate") {
    if (!arg.is_object() || !arg.contains("axis") || !arg.contains("angle") || !arg.at("angle").is_number())
      fail("'" + k + "': rotate needs {\"axis\": [x, y, z], \"angle\": degrees} (got " + brief(arg) + ")");
    only_keys("rotate (known: axis, angle)", {"axis", "angle"});
    return Transform::rotate(vec3d(arg.at("axis")), arg.at("angle").get<double>());
  }
  if (op == "look_at") {
    if (!arg.is_object() || !arg.contains("origin") || !arg.contains("target"))
      fail("'" + k + "': look_at needs origin, target and up (got " + brief(arg) + ")");
    only_keys("look_at (known: origin, target, up)", {"origin", "target", "up"});
    return Transform::look_at(vec3d(arg.at("origin")), vec3d(arg.at("target")),
                              arg.contains("up") ? vec3d(arg.at("up")) : Vec3d(0, 0, 1));
  }
  fail("'" + k + "': unknown transform '" + printable(op, 40) + "' (known: translate, scale, rotate, look_at, matrix)");
}

std::string type_of(const json& j) { return j.at("type").get<std::string>(); }

double norm(const Vec3d& v) { return std::hypot(v.x, v.y, v.z); }

std::string shape_text(const std::vector<size_t>& shape) {
  std::string out = "(";
  for (size_t i = 0; i < shape.size(); ++i) out += (i ? ", " : "") + std::to_string(shape[i]);
  return out + (shape.size() == 1 ? ",)" : ")");
}

bool valid_id(const std::string& id) {
  if (id.empty() || id.size() > 256 || printable(id, 300) != id) return false;  // control characters or invalid UTF-8
  return true;
}

std::string describe(const std::string& kind, const std::string& id, const std::string& type) {
  return kind + " '" + id + "' (" + type + ")";
}

double check_similarity(const Props& p, const Transform& t, const std::string& k) {
  const Mat4d& m = t.matrix();
  const double sx = norm(Vec3d(m[0])), sy = norm(Vec3d(m[1])), sz = norm(Vec3d(m[2]));
  const double tol = 1e-5 * std::max(sx, std::max(sy, sz));
  // The axes' dot products on unit axes (no overflow at any scale): |cos| <= 1e-5.
  const Vec3d ux = Vec3d(m[0]) / sx, uy = Vec3d(m[1]) / sy, uz = Vec3d(m[2]) / sz;
  if (std::abs(sx - sy) > tol || std::abs(sx - sz) > tol || std::abs(glm::dot(ux, uy)) > 1e-5 || std::abs(glm::dot(ux, uz)) > 1e-5 ||
      std::abs(glm::dot(uy, uz)) > 1e-5)
    p.fail("'" + k + "' must be a rotation, uniform scale and translation (its axes have lengths " + number_text(sx) + ", " + number_text(sy) +
           ", " + number_text(sz) + ")");
  return sx;
}

std::string nested_id(const Props& p, const json& child, const std::string& owner) {
  if (!child.contains("id")) return owner;
  if (!child.at("id").is_string()) p.fail("nested \"id\" must be a string (got " + brief(child.at("id")) + ")");
  const std::string id = child.at("id").get<std::string>();
  if (!valid_id(id)) p.fail("nested \"id\" " + brief(child.at("id")) + " is not a valid id (1 to 256 characters, no control characters)");
  if (!p.ctx().ids.insert(id).second) p.fail("duplicate id '" + id + "'");
  return id;
}

}  // namespace limn::io_detail
