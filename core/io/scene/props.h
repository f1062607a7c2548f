// What every scene loader shares (core/io/scene/*): the table of known types, the loading context,
// and Props, the validated typed accessors over one object of the description.
#pragma once
#include <filesystem>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>
#include "core/io/scene/array_data.h"
#include "core/io/scene/json_text.h"
#include "core/render/scene.h"

namespace limn::io_detail {

// j[key] if it is a string, else `def`; wrong types are reported by the caller's checks, never as
// nlohmann exceptions.
std::string str_field(const json& j, const char* key, const std::string& def);

enum class Category { Scene, Sensor, Film, Sampler, Filter, Integrator, Shape, Bsdf, Emitter, Texture, Ref };

// Every type name of the scene format and its category; the shape kinds come from shape_kinds().
const std::map<std::string, Category>& known_types();
// The names of one category, comma-separated, for error messages.
std::string known_of(Category c);

struct Context {
  std::string source;
  std::filesystem::path base_dir;
  const std::vector<ArrayData>* arrays = nullptr;
  Scene* scene = nullptr;
  std::map<std::string, int> named_bsdfs;  // top-level bsdf id -> index
  std::set<std::string> ids;
};

// One object of the description: typed accessors that validate values, record which keys were
// read (the rest are reported as unused) and phrase errors as "<source>: <object>: <problem>".
class Props {
 public:
  Props(Context& ctx, const json& j, std::string what) : m_ctx(ctx), m_j(j), m_what(std::move(what)) {
    m_used.insert("type");
    m_used.insert("id");
  }

  [[noreturn]] void fail(const std::string& msg) const {
    throw std::invalid_argument(m_ctx.source + ": " + m_what + ": " + msg);
  }
  const std::string& what() const { return m_what; }
  // A value for an error message: io_detail::brief, but an array passed from Python (numpy) as
  // "an array of shape (...)" rather than its placeholder {"__limn_array__": i}.
  std::string brief(const json& v) const;
  Context& ctx() const { return m_ctx; }
  bool has(const std::string& k) const { return m_j.contains(k); }
  const json& raw(const std::string& k) const {
    m_used.insert(k);
    return m_j.at(k);
  }

  float number(const std::string& k, float def) const { return has(k) ? number(k) : def; }
  float number(const std::string& k) const;
  int integer(const std::string& k, int def) const;
  bool boolean(const std::string& k, bool def) const;
  std::string string(const std::string& k, const std::string& def) const;
  std::string required_string(const std::string& k) const;
  // A file path relative to the scene file's folder; it must exist.
  std::string file(const std::string& k) const;

  std::vector<double> numbers(const json& v, const std::string& k, size_t n) const;
  Vec3 vec3(const std::string& k, const Vec3& def) const;
  // A number (grey), a list [r, g, b], or {"type": "rgb", "value": ...}.
  Spectrum spectrum(const std::string& k, const Spectrum& def) const;
  Spectrum spectrum_value(const json& v0, const std::string& k) const;
  // A colour or {"type": "bitmap", "filename": ..., "raw": false}.
  Texture texture(const std::string& k, const Spectrum& def) const;

  const ArrayData& array_ref(const json& v, const std::string& k) const;
  // A dense array from nested JSON lists or from an array passed alongside the dictionary.
  ArrayData array(const std::string& k) const;

  // Refused: non-finite entries (also of the inverse), a last row other than [0, 0, 0, 1], singular
  // or nearly singular (the determinant of its unit axes below 1e-12).
  Transform transform(const std::string& k) const;
  void check_transform(const Transform& t, const std::string& k) const;

  // Nested objects (values that are dictionaries with a "type"), in file order.
  std::vector<std::pair<std::string, const json*>> children() const;
  void mark_used(const std::string& k) const { m_used.insert(k); }

  void check_unused() const;

 private:
  Transform parse_transform(const json& v, const std::string& k) const;

  Context& m_ctx;
  const json& m_j;
  std::string m_what;
  mutable std::set<std::string> m_used;
};

std::string type_of(const json& j);

// Length without overflow or underflow at any scale (glm::length squares).
double norm(const Vec3d& v);

// "(4, 3)"
std::string shape_text(const std::vector<size_t>& shape);

// An id (a key of the description or an "id" value) must have 1 to 256 characters and no control
// characters: it names parameters ("<id>.center") and appears in every message about its object.
bool valid_id(const std::string& id);

std::string describe(const std::string& kind, const std::string& id, const std::string& type);

// Fails unless `t` (the value of `k`) is a rotation, uniform scale and translation; returns its
// scale factor.
double check_similarity(const Props& p, const Transform& t, const std::string& k = "to_world");

// An explicit "id" on a nested object must be unique like the top-level ones; without one the
// object is named after its owner.
std::string nested_id(const Props& p, const json& child, const std::string& owner);

}  // namespace limn::io_detail
