#include "palpa/io/escape.h"

#include <algorithm>
#include <cstdint>
#include <cstdio>

namespace palpa::io {
namespace {

// Length of the well-formed UTF-8 sequence at s[0] (2-4), or 0. Overlong forms, surrogates,
// code points above U+10FFFF and C1 controls (U+0080-U+009F: terminals act on them) give 0.
std::size_t Utf8Length(std::string_view s) {
  const auto b = [&](std::size_t i) { return static_cast<unsigned char>(s[i]); };
  const unsigned char c = b(0);
  std::size_t n = 0;
  std::uint32_t cp = 0;
  if (c >= 0xC2 && c <= 0xDF) {
    n = 2, cp = c & 0x1FU;
  } else if (c >= 0xE0 && c <= 0xEF) {
    n = 3, cp = c & 0x0FU;
  } else if (c >= 0xF0 && c <= 0xF4) {
    n = 4, cp = c & 0x07U;
  } else {
    return 0;
  }
  if (s.size() < n) return 0;
  for (std::size_t i = 1; i < n; ++i) {
    if ((b(i) & 0xC0U) != 0x80U) return 0;
    cp = (cp << 6) | (b(i) & 0x3FU);
  }
  if ((n == 3 && cp < 0x800) || (n == 4 && cp < 0x10000) || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF) ||
      (cp >= 0x80 && cp <= 0x9F))
    return 0;
  return n;
}

}  // namespace

std::string Escape(std::string_view bytes, std::size_t max_bytes) {
  std::string out;
  out.reserve(std::min(bytes.size(), max_bytes) + 8);
  std::size_t i = 0;
  while (i < bytes.size()) {
    const unsigned char c = static_cast<unsigned char>(bytes[i]);
    const std::size_t n = c >= 0x80 ? Utf8Length(bytes.substr(i)) : 1;
    if (i + (n == 0 ? 1 : n) > max_bytes) break;
    if (n >= 2) {
      out.append(bytes.substr(i, n));
      i += n;
      continue;
    }
    if (c == '\\') {
      out += "\\\\";
    } else if (c == '\t') {
      out += "\\t";
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (c < 0x20 || c >= 0x7F) {
      char hex[5];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      out += hex;
    } else {
      out += static_cast<char>(c);
    }
    ++i;
  }
  if (i < bytes.size()) out += "…";
  return out;
}

}  // namespace palpa::io
