// palpad's config file (--config, e.g. /etc/palpa/palpad.toml): TOML read with toml++ (Debian's
// libtomlplusplus-dev, header-only). Every key is a command-line option without its leading
// "--" (rate = 1000, estop = "gpiochip0:17", fast = true); options.cc checks names and types
// against its option table, so the file and the command line accept exactly the same options.
// Non-RT.
#pragma once

#include <expected>
#include <string>
#include <vector>

namespace palpa::palpad {

/// One top-level key = value of the file.
struct ConfigEntry {
  enum class Kind { kString, kNumber, kBoolean, kOther };
  std::string key;  ///< as written, e.g. "max-force"
  Kind kind = Kind::kOther;
  std::string text;      ///< kString: the string
  double number = 0;     ///< kNumber: TOML integer or float
  bool boolean = false;  ///< kBoolean
  std::string type;      ///< kOther: the TOML type ("table", "array", "date", …) for the error message
  int line = 0;          ///< 1-based line of the key
};

/// Reads and parses `path` (a regular file of at most 1 MiB: io::ReadBounded); entries in file
/// order (by line). Errors name the file and line, e.g.
/// "palpad.toml:3:7: expected '=' …" or "palpad.toml: cannot read: No such file or directory".
std::expected<std::vector<ConfigEntry>, std::string> ReadConfigFile(const std::string& path);

/// As ReadConfigFile, from text (`source` names it in errors).
std::expected<std::vector<ConfigEntry>, std::string> ParseConfigText(const std::string& text,
                                                                     const std::string& source);

}  // namespace palpa::palpad
