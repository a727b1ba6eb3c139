// GPIO lines through libgpiod v1.6 (Debian 12's libgpiod2), the kernel's GPIO character device.
// Each object owns its chip handle and its line request; destruction releases both.
//
// Errors name the option, the chip and the line, and say what the system said, e.g.
// "--estop gpiochip0:17: cannot open GPIO chip 'gpiochip0': No such file or directory (this system
// has no such chip; `gpiodetect` lists the chips)".
//
// Thread/RT rules: Open* and destruction are non-RT. Read/Set are one ioctl each
// (GPIOHANDLE_GET/SET_LINE_VALUES_IOCTL): no allocation or lock; the servo thread calls them.
#pragma once

#include <expected>
#include <memory>
#include <string>
#include <string_view>

#include "palpa/gpio/gpio.h"

struct gpiod_chip;
struct gpiod_line;

namespace palpa::gpio_linux {

/// An input line, requested as "input" under `consumer` (shown by `gpioinfo`).
class GpiodInput final : public gpio::DigitalInput {
 public:
  /// `option` (e.g. "--estop") prefixes error messages.
  static std::expected<std::unique_ptr<GpiodInput>, std::string> Open(std::string_view option,
                                                                      const gpio::LineSpec& spec, const char* consumer);
  ~GpiodInput() override;

 private:
  GpiodInput(gpiod_chip* chip, gpiod_line* line) : chip_(chip), line_(line) {}
  gpio::GpioStatus DoRead(bool& level) override;

  gpiod_chip* chip_;
  gpiod_line* line_;
};

/// An output line, requested as "output" under `consumer`, driven to `initial` at once.
class GpiodOutput final : public gpio::DigitalOutput {
 public:
  static std::expected<std::unique_ptr<GpiodOutput>, std::string> Open(std::string_view option,
                                                                       const gpio::LineSpec& spec, const char* consumer,
                                                                       bool initial);
  ~GpiodOutput() override;

 private:
  GpiodOutput(gpiod_chip* chip, gpiod_line* line) : chip_(chip), line_(line) {}
  gpio::GpioStatus DoSet(bool level) override;

  gpiod_chip* chip_;
  gpiod_line* line_;
};

}  // namespace palpa::gpio_linux
