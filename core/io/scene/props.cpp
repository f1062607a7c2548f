#include "core/io/scene/props.h"

#include <functional>
#include <stdexcept>
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
  if (!v.is_number()) fail("'" + k + "' must be a number (got " + v.dump() + ")");
  const double d = v.get<double>();
  if (!std::isfinite(d) || !std::isfinite(float(d)) || std::abs(d) > 3.0e38)
    fail("'" + k + "' must be a finite float (got " + v.dump() + ")");
  return float(d);
}

int Props::integer(const std::string& k, int def) const {
  if (!has(k)) return def;
  const json& v = raw(k);
  if (!v.is_number_integer()) fail("'" + k + "' must be an integer (got " + v.dump() + ")");
  const int64_t i = v.get<int64_t>();
  if (i < -(int64_t(1) << 30) || i > (int64_t(1) << 30)) fail("'" + k + "' is out of range (got " + v.dump() + ")");
  return int(i);
}

bool Props::boolean(const std::string& k, bool def) const {
  if (!has(k)) return def;
  const json& v = raw(k);
  if (!v.is_boolean()) fail("'" + k + "' must be true or false (got " + v.dump() + ")");
  return v.get<bool>();
}

std::string Props::string(const std::string& k, const std::string& def) const {
  if (!has(k)) return def;
  const json& v = raw(k);
  if (!v.is_string()) fail("'" + k + "' must be a string (got " + v.dump() + ")");
  return v.get<std::string>();
}

std::string Props::required_string(const std::string& k) const {
  if (!has(k)) fail("missing parameter '" + k + "'");
  return string(k, "");
}

std::string Props::file(const std::string& k) const {
  const std::string name = required_string(k);
  std::filesystem::path p(name);
  if (p.is_relative()) p = m_ctx.base_dir / p;
  std::error_code ec;
  if (!std::filesystem::exists(p, ec)) fail("file '" + name + "' not found (looked for " + p.string() + ")");
  return p.string();
}

std::vector<double> Props::numbers(const json& v, const std::string& k, size_t n) const {
  if (v.is_object() && v.contains("__limn_array__")) {
    const ArrayData& a = array_ref(v, k);
    if (a.values.size() != n) fail("'" + k + "' must have " + std::to_string(n) + " values (got " + std::to_string(a.values.size()) + ")");
    for (double d : a.values) if (!(std::abs(d) <= 3.0e38)) fail("'" + k + "' has a non-finite entry");
    return a.values;
  }
  if (!v.is_array() || v.size() != n) fail("'" + k + "' must be a list of " + std::to_string(n) + " numbers (got " + v.dump() + ")");
  std::vector<double> out;
  for (const json& e : v) {
    if (!e.is_number() || !(std::abs(e.get<double>()) <= 3.0e38)) fail("'" + k + "' must contain finite float numbers (got " + v.dump() + ")");
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
  else if (v->is_object() && v->contains("type")) fail("'" + k + "' must be a colour (number, [r, g, b] or rgb), not " + v->dump());
  else {
    const auto n = numbers(*v, k, 3);
    s = Spectrum(float(n[0]), float(n[1]), float(n[2]));
  }
  if (!is_finite(s) || s.x < 0.0f || s.y < 0.0f || s.z < 0.0f) fail("'" + k + "' must be finite and >= 0 (got " + v->dump() + ")");
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
      bp.fail(e.what());
    }
    bp.check_unused();
    return t;
  }
  t.value = spectrum_value(v, k);
  return t;
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
  ArrayData a;
  std::function<void(const json&, size_t)> walk = [&](const json& e, size_t depth) {
    if (e.is_array()) {
      if (a.shape.size() <= depth) a.shape.push_back(e.size());
      else if (a.shape[depth] != e.size()) fail("'" + k + "' is a ragged array");
      for (const json& x : e) walk(x, depth + 1);
    } else if (e.is_number()) {
      if (depth != a.shape.size()) fail("'" + k + "' is a ragged array");
      a.values.push_back(e.get<double>());
      a.integer = a.values.size() == 1 ? e.is_number_integer() : a.integer && e.is_number_integer();
    } else {
      fail("'" + k + "' must be an array of numbers");
    }
  };
  walk(v, 0);
  size_t count = 1;
  for (size_t n : a.shape) count *= n;
  if (count != a.values.size()) fail("'" + k + "' is a ragged array");
  return a;
}

Transform Props::transform(const std::string& k) const {
  if (!has(k)) return Transform();
  try {
    return parse_transform(raw(k), k);
  } catch (const std::invalid_argument& e) {
    if (std::string(e.what()).rfind(m_ctx.source, 0) == 0) throw;
    fail("'" + k + "': " + e.what());
  }
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
  for (auto it = m_j.begin(); it != m_j.end(); ++it)
    if (!m_used.count(it.key()))
      m_ctx.scene->warnings.push_back(m_ctx.source + ": " + m_what + ": unused parameter '" + it.key() + "'");
}

Transform Props::parse_transform(const json& v, const std::string& k) const {
  auto matrix = [&](const json& m) {
    if (m.is_object() && m.contains("__limn_array__")) {
      const ArrayData& a = array_ref(m, k);
      if (a.values.size() != 16) fail("'" + k + "' matrix must be 4x4");
      Mat4d out;
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) out[c][r] = a.values[size_t(r) * 4 + c];
      return Transform(out);
    }
    if (!m.is_array() || m.size() != 4) fail("'" + k + "' matrix must be a list of 4 rows of 4 numbers");
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
    fail("'" + k + "' must be a 4x4 matrix, one of {translate, scale, rotate, look_at, matrix}, or a list of them (got " + v.dump() + ")");
  // The one key and its value (not a structured binding to *v.items().begin(): the proxy it
  // refers to dies at the end of that statement; AddressSanitizer found the dangling read).
  const auto step = v.begin();
  const std::string op = step.key();
  const json& arg = step.value();
  if (op == "translate") return Transform::translate(vec3d(arg));
  if (op == "scale") return Transform::scale(arg.is_number() ? Vec3d(arg.get<double>()) : vec3d(arg));
  if (op == "matrix") return matrix(arg);
  if (op == "rotate") {
    if (!arg.is_object() || !arg.contains("axis") || !arg.contains("angle") || !arg.at("angle").is_number())
      fail("'" + k + "': rotate needs {\"axis\": [x, y, z], \"angle\": degrees}");
    return Transform::rotate(vec3d(arg.at("axis")), arg.at("angle").get<double>());
  }
  if (op == "look_at") {
    if (!arg.is_object() || !arg.contains("origin") || !arg.contains("target"))
      fail("'" + k + "': look_at needs origin, target and up");
    return Transform::look_at(vec3d(arg.at("origin")), vec3d(arg.at("target")),
                              arg.contains("up") ? vec3d(arg.at("up")) : Vec3d(0, 0, 1));
  }
  fail("'" + k + "': unknown transform '" + op + "' (known: translate, scale, rotate, look_at, matrix)");
}

std::string type_of(const json& j) { return j.at("type").get<std::string>(); }

std::string describe(const std::string& kind, const std::string& id, const std::string& type) {
  return kind + " '" + id + "' (" + type + ")";
}

void check_similarity(const Props& p, const Transform& t, float& scale) {
  const Mat4d& m = t.matrix();
  const double sx = glm::length(Vec3d(m[0])), sy = glm::length(Vec3d(m[1])), sz = glm::length(Vec3d(m[2]));
  const double tol = 1e-5 * std::max(sx, std::max(sy, sz));
  if (std::abs(sx - sy) > tol || std::abs(sx - sz) > tol || std::abs(glm::dot(Vec3d(m[0]), Vec3d(m[1]))) > tol * sx ||
      std::abs(glm::dot(Vec3d(m[0]), Vec3d(m[2]))) > tol * sx || std::abs(glm::dot(Vec3d(m[1]), Vec3d(m[2]))) > tol * sx)
    p.fail("to_world must be a rotation, uniform scale and translation");
  scale = float(sx);
}

std::string nested_id(const Props& p, const json& child, const std::string& owner) {
  if (!child.contains("id")) return owner;
  if (!child.at("id").is_string()) p.fail("nested \"id\" must be a string (got " + child.at("id").dump() + ")");
  const std::string id = child.at("id").get<std::string>();
  if (!p.ctx().ids.insert(id).second) p.fail("duplicate id '" + id + "'");
  return id;
}

}  // namespace limn::io_detail
