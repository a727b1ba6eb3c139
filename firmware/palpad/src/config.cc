#include "palpa/palpad/config.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string_view>

#include <toml++/toml.h>

namespace palpa::palpad {
namespace {

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
                           std::to_string(e.source().begin.column) + ": " + std::string(e.description()));
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
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return std::unexpected(path + ": cannot read the config file: " + std::strerror(errno));
  std::string text;
  char buf[4096];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) return std::unexpected(path + ": cannot read the config file");
  return ParseConfigText(text, path);
}

}  // namespace palpa::palpad
