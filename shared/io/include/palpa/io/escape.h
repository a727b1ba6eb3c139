// Quoting input bytes in messages (issue 18, finding 8): a crafted file must not reach the
// operator's terminal as escape sequences, nor fill it. Header-light so that the PLY fuzzer (clang)
// compiles it alone.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace palpa::io {

/// Quotes `bytes` for a message: printable ASCII and well-formed UTF-8 (C1 controls excepted)
/// pass; control characters, ESC, NUL, DEL, backslash and bytes that are not UTF-8 become \t, \n,
/// \r, \\ or \xNN. At most `max_bytes` input bytes are quoted (cut at a character boundary); a
/// longer input ends in "…". The result never holds a byte a terminal would interpret.
[[nodiscard]] std::string Escape(std::string_view bytes, std::size_t max_bytes = 64);

}  // namespace palpa::io
