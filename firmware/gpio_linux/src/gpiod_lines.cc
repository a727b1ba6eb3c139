#include "palpa/gpio_linux/gpiod_lines.h"

#include <gpiod.h>

#include <cerrno>
#include <cstring>

namespace palpa::gpio_linux {
namespace {

std::string Where(std::string_view option, const gpio::LineSpec& spec) {
  return std::string(option) + " " + spec.chip + ":" + std::to_string(spec.line);
}

// A chip given as a path opens that node; a bare name opens /dev/<name> (libgpiod's by-name).
gpiod_chip* OpenChip(const std::string& chip) {
  return chip.starts_with('/') ? gpiod_chip_open(chip.c_str()) : gpiod_chip_open_by_name(chip.c_str());
}

struct Opened {
  gpiod_chip* chip;
  gpiod_line* line;
};

// Opens the chip and finds the line; on failure closes what it opened and says why.
std::expected<Opened, std::string> OpenLine(std::string_view option, const gpio::LineSpec& spec) {
  errno = 0;
  gpiod_chip* chip = OpenChip(spec.chip);
  if (chip == nullptr) {
    const int err = errno != 0 ? errno : ENODEV;
    std::string message = Where(option, spec) + ": cannot open GPIO chip '" + spec.chip + "': " + std::strerror(err);
    if (err == ENOENT || err == ENODEV || err == ENOTTY)
      message += " (this system has no such chip; `gpiodetect` lists the chips)";
    if (err == EACCES || err == EPERM) message += " (no permission: run as root or add the user to group gpio)";
    return std::unexpected(std::move(message));
  }
  const unsigned lines = gpiod_chip_num_lines(chip);
  if (spec.line >= lines) {
    gpiod_chip_close(chip);
    return std::unexpected(Where(option, spec) + ": GPIO chip '" + spec.chip + "' has lines 0.." +
                           std::to_string(lines == 0 ? 0 : lines - 1) + " only");
  }
  errno = 0;
  gpiod_line* line = gpiod_chip_get_line(chip, spec.line);
  if (line == nullptr) {
    const int err = errno != 0 ? errno : EINVAL;
    gpiod_chip_close(chip);
    return std::unexpected(Where(option, spec) + ": cannot get line " + std::to_string(spec.line) + " of '" +
                           spec.chip + "': " + std::strerror(err));
  }
  return Opened{chip, line};
}

std::string RequestError(std::string_view option, const gpio::LineSpec& spec, const char* as) {
  const int err = errno != 0 ? errno : EIO;
  std::string message = Where(option, spec) + ": cannot request line " + std::to_string(spec.line) + " as " + as +
                        ": " + std::strerror(err);
  if (err == EBUSY) message += " (another program holds it; `gpioinfo` shows the consumer)";
  return message;
}

}  // namespace

std::expected<std::unique_ptr<GpiodInput>, std::string> GpiodInput::Open(std::string_view option,
                                                                         const gpio::LineSpec& spec,
                                                                         const char* consumer) {
  auto opened = OpenLine(option, spec);
  if (!opened) return std::unexpected(std::move(opened.error()));
  errno = 0;
  if (gpiod_line_request_input(opened->line, consumer) != 0) {
    std::string message = RequestError(option, spec, "input");
    gpiod_chip_close(opened->chip);
    return std::unexpected(std::move(message));
  }
  return std::unique_ptr<GpiodInput>(new GpiodInput(opened->chip, opened->line));
}

GpiodInput::~GpiodInput() {
  gpiod_line_release(line_);
  gpiod_chip_close(chip_);
}

gpio::GpioStatus GpiodInput::DoRead(bool& level) {
  const int v = gpiod_line_get_value(line_);
  if (v < 0) return gpio::GpioStatus::kError;
  level = v != 0;
  return gpio::GpioStatus::kOk;
}

std::expected<std::unique_ptr<GpiodOutput>, std::string> GpiodOutput::Open(std::string_view option,
                                                                           const gpio::LineSpec& spec,
                                                                           const char* consumer, bool initial) {
  auto opened = OpenLine(option, spec);
  if (!opened) return std::unexpected(std::move(opened.error()));
  errno = 0;
  if (gpiod_line_request_output(opened->line, consumer, initial ? 1 : 0) != 0) {
    std::string message = RequestError(option, spec, "output");
    gpiod_chip_close(opened->chip);
    return std::unexpected(std::move(message));
  }
  return std::unique_ptr<GpiodOutput>(new GpiodOutput(opened->chip, opened->line));
}

GpiodOutput::~GpiodOutput() {
  gpiod_line_release(line_);
  gpiod_chip_close(chip_);
}

gpio::GpioStatus GpiodOutput::DoSet(bool level) {
  return gpiod_line_set_value(line_, level ? 1 : 0) == 0 ? gpio::GpioStatus::kOk : gpio::GpioStatus::kError;
}

}  // namespace palpa::gpio_linux
