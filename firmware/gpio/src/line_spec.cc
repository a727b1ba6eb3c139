#include <charconv>

#include "palpa/gpio/gpio.h"

namespace palpa::gpio {

std::expected<LineSpec, std::string> ParseLineSpec(std::string_view option, std::string_view text) {
  const std::string prefix = std::string(option) + ": '" + std::string(text) + "' ";
  const auto colon = text.rfind(':');
  if (colon == std::string_view::npos) return std::unexpected(prefix + "is not CHIP:LINE (e.g. gpiochip0:17)");
  const std::string_view chip = text.substr(0, colon);
  const std::string_view line = text.substr(colon + 1);
  if (chip.empty()) return std::unexpected(prefix + "names no chip (CHIP:LINE, e.g. gpiochip0:17)");
  unsigned value = 0;
  const char* end = line.data() + line.size();
  const auto [ptr, ec] = std::from_chars(line.data(), end, value);
  if (line.empty() || ec != std::errc() || ptr != end || value > 65535)
    return std::unexpected(prefix + "has no line number in 0..65535 after the ':'");
  return LineSpec{std::string(chip), value};
}

std::expected<bool, std::string> ParseActiveLevel(std::string_view option, std::string_view text) {
  if (text == "high") return true;
  if (text == "low") return false;
  return std::unexpected(std::string(option) + ": '" + std::string(text) + "' is not high or low");
}

}  // namespace palpa::gpio
