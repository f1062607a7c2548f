// Scene descriptions as JSON values: parsing text with limits (nesting depth, duplicate keys,
// numbers out of the range of double, invalid UTF-8, each reported with the source and the line
// and column or the key), converting descriptions built elsewhere, and quoting values in error
// messages without ever printing an unbounded value.
#pragma once
#include <cstddef>
#include <string>
#include <string_view>
#include <nlohmann/json.hpp>

namespace limn::io_detail {

// Objects keep their keys in file order (Props::children() lists nested objects in that order).
using json = nlohmann::ordered_json;

// Containers nested deeper than this are refused (no real scene comes close; the limit keeps every
// recursive walk over a description shallow).
inline constexpr size_t kMaxJsonDepth = 256;

// Parses `text`; throws std::invalid_argument("<source>: ...") naming the line and column (and the
// key where it is known) of a syntax error, invalid UTF-8, a number out of the range of double,
// nesting deeper than kMaxJsonDepth, or a key repeated in one object.
json parse_scene_json(std::string_view text, const std::string& source);

// A description built as nlohmann::json (keys in sorted order); refuses nesting deeper than
// kMaxJsonDepth, checked without recursion.
json to_ordered(const nlohmann::json& j, const std::string& source);

// `j` as compact JSON for an error message, cut to about `max_chars` characters and a few levels of
// nesting (never nlohmann's dump() of a whole, possibly huge or deep, value).
std::string brief(const json& j, size_t max_chars = 80);

}  // namespace limn::io_detail
