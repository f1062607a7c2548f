// What every reader of untrusted files shares: refusing what is not a regular file before opening
// it (a FIFO would block, a directory is not data), reading with a size limit, and quoting file
// content in error messages as valid UTF-8 (Python cannot show a message with invalid UTF-8).
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace limn {

// Throws std::invalid_argument("<what> '<path>' not found" / "... is a directory, not a file" /
// "... is not a regular file (a FIFO, socket or device)") unless `path` names a regular file.
// Returns its size in bytes.
uint64_t check_regular_file(const std::string& path, const std::string& what);

// The whole file (after check_regular_file); refuses files larger than `max_bytes`.
std::string read_file_bytes(const std::string& path, const std::string& what, uint64_t max_bytes);

// `text` with every byte that is not part of valid UTF-8, and every control character, written as
// \xNN; cut to about `max_chars` characters ("..." marks the cut).
std::string printable(std::string_view text, size_t max_chars = 200);

// Whether `text` is valid UTF-8 (no overlong forms, no surrogates).
bool valid_utf8(std::string_view text);

// 1-based line and column of byte `offset` in `text`.
struct TextPosition {
  size_t line = 1, column = 1;
};
TextPosition text_position(std::string_view text, size_t offset);

// A number as the shortest text that reads back to it ("1e+300", "0.5", "nan"); a float as a float
// (0.6f is "0.6", not "0.6000000238418579").
std::string number_text(double v);
std::string number_text(float v);

}  // namespace limn
