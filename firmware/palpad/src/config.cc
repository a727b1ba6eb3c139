#include "palpa/palpad/config.h"

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string_view>

#include <toml++/toml.h>

#include "palpa/io/escape.h"
#include "palpa/io/file_safety.h"

namespace palpa::palpad {
namespace {

constexpr std::uint64_t kMaxConfigBytes = 1 << 20;  // a config is a few dozen lines

const char* TypeName(toml::node_type t) {
  switch (t) {
    case toml::node_type::table:
      return "table";
    case toml::node_type::array:
      return "array";
    case toml::node_type::date:
      return "date";
    case toml::node_type::time:
      return "time";
    case toml::node_type::date_time:
      return "date-time";
    default:
      return "value";
  }
}

}  // namespace

std::expected<std::vector<ConfigEntry>, std::string> ParseConfigText(const std::string& text,
                                                                     const std::string& source) {
  toml::parse_result parsed = toml::parse(std::string_view(text), std::string_view(source));
  if (!parsed) {
    const toml::parse_error& e = parsed.error();
    return std::unexpected(source + ":" + std::to_string(e.source().begin.line) + ":" +
                           std::to_string(e.source().begin.column) + ": " + io::Escape(e.description(), 256));
  }
  std::vector<ConfigEntry> entries;
  for (auto&& [key, node] : parsed.table()) {
    ConfigEntry e;
    e.key = std::string(key.str());
    e.line = static_cast<int>(key.source().begin.line);
    if (const auto* s = node.as_string()) {
      e.kind = ConfigEntry::Kind::kString;
      e.text = s->get();
    } else if (const auto* i = node.as_integer()) {
      e.kind = ConfigEntry::Kind::kNumber;
      e.number = static_cast<double>(i->get());
    } else if (const auto* f = node.as_floating_point()) {
      e.kind = ConfigEntry::Kind::kNumber;
      e.number = f->get();
    } else if (const auto* b = node.as_boolean()) {
      e.kind = ConfigEntry::Kind::kBoolean;
      e.boolean = b->get();
    } else {
      e.kind = ConfigEntry::Kind::kOther;
      e.type = TypeName(node.type());
    }
    entries.push_back(std::move(e));
  }
  std::stable_sort(entries.begin(), entries.end(),
                   [](const ConfigEntry& a, const ConfigEntry& b) { return a.line < b.line; });
  return entries;
}

std::expected<std::vector<ConfigEntry>, std::string> ReadConfigFile(const std::string& path) {
  // A regular file of at most 1 MiB (a FIFO or /dev/zero is refused before any read).
  auto text = io::ReadBoundedText(path, kMaxConfigBytes, "config file");
  if (!text) return std::unexpected(std::move(text.error().message));
  return ParseConfigText(*text, path);
}

}  // namespace palpa::palpad
