#include "core/io/scene/json_text.h"

#include <stdexcept>
#include <unordered_set>
#include <vector>
#include "core/io/formats/files.h"

namespace limn::io_detail {

namespace {

// Key path of an open container, for messages: 'ball.bsdf.reflectance[2]'.
std::string join_path(const std::vector<std::string>& parts) {
  std::string out;
  for (const std::string& p : parts) {
    if (out.size() > 160) {
      out += "...";
      break;
    }
    if (!p.empty() && p[0] == '[') out += p;
    else out += (out.empty() ? "" : ".") + printable(p, 40);
  }
  return out.empty() ? "the top level" : "'" + out + "'";
}

// Builds an ordered_json from nlohmann's SAX events: keys in file order, refusing duplicate keys and
// nesting deeper than kMaxJsonDepth.
class Builder : public nlohmann::json_sax<json> {
 public:
  json root;
  std::string refusal;        // why parsing was stopped by this builder (depth, duplicate key)
  bool too_deep = false;
  bool syntax_error = false;  // nlohmann's parser reported an error
  size_t error_offset = 0;
  std::string error_text;

  bool null() override { return put(json(nullptr)); }
  bool boolean(bool v) override { return put(json(v)); }
  bool number_integer(number_integer_t v) override { return put(json(v)); }
  bool number_unsigned(number_unsigned_t v) override { return put(json(v)); }
  bool number_float(number_float_t v, const string_t&) override { return put(json(v)); }
  bool string(string_t& v) override { return put(json(std::move(v))); }
  bool binary(binary_t&) override {
    refusal = "binary values are not part of JSON";
    return false;
  }
  bool start_object(std::size_t) override { return open(json::object()); }
  bool key(string_t& k) override {
    Frame& f = m_stack.back();
    if (!f.keys.insert(k).second) {
      refusal = "the key '" + printable(k, 60) + "' appears twice in " + path(false);
      return false;
    }
    f.key = std::move(k);
    return true;
  }
  bool end_object() override { return close(); }
  bool start_array(std::size_t) override { return open(json::array()); }
  bool end_array() override { return close(); }
  bool parse_error(std::size_t position, const std::string&, const nlohmann::detail::exception& ex) override {
    syntax_error = true;
    error_offset = position;
    error_text = ex.what();
    return false;
  }

  // Where the parser is: the key path of the open containers and (with `pending`) the last key read
  // in the innermost object.
  std::string path(bool pending = true) const {
    std::vector<std::string> parts;
    for (size_t i = 0; i < m_stack.size(); ++i) {
      const Frame& f = m_stack[i];
      const bool inner = i + 1 == m_stack.size();
      const size_t n = f.value->size();  // an open child is the last element; the next value comes after it
      if (f.value->is_array()) parts.push_back("[" + std::to_string(!inner && n > 0 ? n - 1 : n) + "]");
      else if ((!inner || pending) && !f.keys.empty()) parts.push_back(f.key);
    }
    return join_path(parts);
  }

 private:
  struct Frame {
    json* value;
    std::unordered_set<std::string> keys;
    std::string key;
  };

  json* put(json&& v) {
    if (m_stack.empty()) {
      root = std::move(v);
      return &root;
    }
    Frame& f = m_stack.back();
    if (f.value->is_array()) {
      auto& a = f.value->get_ref<json::array_t&>();
      a.push_back(std::move(v));
      return &a.back();
    }
    auto& o = f.value->get_ref<json::object_t&>();  // ordered_map: a vector of pairs; the key is new
    static_cast<json::object_t::Container&>(o).emplace_back(f.key, std::move(v));
    return &o.back().second;
  }
  bool open(json&& v) {
    if (m_stack.size() >= kMaxJsonDepth) {
      too_deep = true;
      refusal = "values nest deeper than " + std::to_string(kMaxJsonDepth) + " levels (in " + path() + ")";
      return false;
    }
    json* slot = put(std::move(v));
    m_stack.push_back(Frame{slot, {}, {}});
    return true;
  }
  bool close() {
    m_stack.pop_back();
    return true;
  }

  std::vector<Frame> m_stack;
};

// Byte offset of the bracket that opens nesting level `level` (1 = the outermost), outside strings.
size_t offset_of_level(std::string_view text, size_t level) {
  size_t depth = 0;
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth == level) return i;
    } else if (c == ']' || c == '}') {
      if (depth > 0) --depth;
    }
  }
  return text.size();
}

// nlohmann's message without its "[json.exception...] parse error at line L, column C: " prefix.
std::string parser_message(const std::string& what) {
  std::string m = what;
  if (const size_t col = m.find(", column "); col != std::string::npos) {
    if (const size_t colon = m.find(": ", col); colon != std::string::npos) m = m.substr(colon + 2);
  } else if (const size_t bracket = m.find("] "); bracket != std::string::npos) {
    m = m.substr(bracket + 2);
  }
  return printable(m, 200);
}

void brief_into(const json& j, std::string& out, size_t max_chars, int depth) {
  if (out.size() > max_chars) return;
  if (j.is_array() || j.is_object()) {
    const bool array = j.is_array();
    if (depth >= 4 && !j.empty()) {
      out += array ? "[...]" : "{...}";
      return;
    }
    out += array ? '[' : '{';
    bool first = true;
    for (auto it = j.begin(); it != j.end(); ++it) {
      if (!first) out += ',';
      first = false;
      if (out.size() > max_chars) {
        out += "...";
        break;
      }
      if (!array) out += json(printable(it.key(), 40)).dump() + ":";
      brief_into(it.value(), out, max_chars, depth + 1);
    }
    out += array ? ']' : '}';
    return;
  }
  if (j.is_string()) {
    out += json(printable(j.get_ref<const std::string&>(), 60)).dump();
    return;
  }
  out += j.dump(-1, ' ', false, json::error_handler_t::replace);  // a number, bool or null
}

}  // namespace

json parse_scene_json(std::string_view text, const std::string& source) {
  Builder b;
  bool ok;
  try {
    ok = json::sax_parse(text.begin(), text.end(), &b, json::input_format_t::json, true, false);
  } catch (const json::exception& e) {  // not expected from sax_parse; reported like a syntax error
    throw std::invalid_argument(source + ": malformed JSON: " + parser_message(e.what()));
  }
  if (ok) return std::move(b.root);
  if (b.syntax_error) {
    const TextPosition p = text_position(text, b.error_offset);
    throw std::invalid_argument(source + ": malformed JSON at line " + std::to_string(p.line) + ", column " + std::to_string(p.column) + " (last key " +
                                b.path() + "): " + parser_message(b.error_text));
  }
  if (b.too_deep) {
    const TextPosition p = text_position(text, offset_of_level(text, kMaxJsonDepth + 1));
    throw std::invalid_argument(source + ": line " + std::to_string(p.line) + ", column " + std::to_string(p.column) + ": " + b.refusal);
  }
  throw std::invalid_argument(source + ": " + (b.refusal.empty() ? std::string("malformed JSON") : b.refusal));
}

json to_ordered(const nlohmann::json& j, const std::string& source) {
  // Depth first, without recursion, before anything recursive touches the value.
  struct Frame {
    const nlohmann::json* v;
    nlohmann::json::const_iterator it;
    size_t index;
  };
  std::vector<Frame> stack;
  if (j.is_structured()) stack.push_back({&j, j.begin(), 0});
  while (!stack.empty()) {
    Frame& f = stack.back();
    if (f.it == f.v->end()) {
      stack.pop_back();
      continue;
    }
    const nlohmann::json& child = *f.it;
    ++f.it;
    ++f.index;
    if (!child.is_structured()) continue;
    if (stack.size() >= kMaxJsonDepth) {
      std::vector<std::string> parts;
      for (const Frame& g : stack) {
        auto prev = std::prev(g.it);
        parts.push_back(g.v->is_array() ? "[" + std::to_string(g.index - 1) + "]" : prev.key());
      }
      throw std::invalid_argument(source + ": values nest deeper than " + std::to_string(kMaxJsonDepth) + " levels (in " + join_path(parts) + ")");
    }
    stack.push_back({&child, child.begin(), 0});
  }
  // Now at most kMaxJsonDepth levels: a recursive copy is safe.
  struct Copy {
    static json run(const nlohmann::json& v) {
      if (v.is_object()) {
        json o = json::object();
        auto& m = o.get_ref<json::object_t&>();
        for (auto it = v.begin(); it != v.end(); ++it) static_cast<json::object_t::Container&>(m).emplace_back(it.key(), run(it.value()));
        return o;
      }
      if (v.is_array()) {
        json a = json::array();
        for (const auto& e : v) a.push_back(run(e));
        return a;
      }
      switch (v.type()) {
        case nlohmann::json::value_t::null: return json(nullptr);
        case nlohmann::json::value_t::boolean: return json(v.get<bool>());
        case nlohmann::json::value_t::number_integer: return json(v.get<int64_t>());
        case nlohmann::json::value_t::number_unsigned: return json(v.get<uint64_t>());
        case nlohmann::json::value_t::number_float: return json(v.get<double>());
        case nlohmann::json::value_t::string: return json(v.get_ref<const std::string&>());
        default: return json(nullptr);  // binary and discarded values do not come from JSON text
      }
    }
  };
  return Copy::run(j);
}

std::string brief(const json& j, size_t max_chars) {
  std::string out;
  brief_into(j, out, max_chars, 0);
  return out;
}

}  // namespace limn::io_detail
