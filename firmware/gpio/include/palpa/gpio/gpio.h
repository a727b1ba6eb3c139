// Digital lines as the servo loop sees them: an input (the e-stop) and an output (the tick line).
// Backends: firmware/gpio_linux/ (libgpiod v1.6, the kernel's GPIO character device) and
// firmware/gpio_sim/ (simulated lines that record {timestamp, value}); palpad picks one, the loop
// never #ifdefs on it (house style §1, §7; after pigweed's pw_digital_io).
//
// Levels are physical (true = high). What "asserted" means (active high or low) is the user's
// wiring and is applied above this layer, so every backend behaves the same.
//
// Thread/RT rules: one thread (the servo thread) calls Read/Set once per tick. RT contract for
// every backend: DoRead/DoSet must not allocate, lock, throw or block beyond the line access
// itself (one ioctl for libgpiod). Opening and closing lines are non-RT.
#pragma once

#include <expected>
#include <string>
#include <string_view>

namespace palpa::gpio {

/// Result of one line access.
enum class GpioStatus {
  kOk,
  kError,  ///< the access failed; the loop treats an e-stop read error as "asserted" (fail-safe)
};

/// NVI: public non-virtual calls, private virtual Do*.
class DigitalInput {
 public:
  DigitalInput() = default;
  DigitalInput(const DigitalInput&) = delete;
  DigitalInput& operator=(const DigitalInput&) = delete;
  virtual ~DigitalInput() = default;

  /// Physical level now (true = high) into `level`. RT-safe per the backend contract.
  GpioStatus Read(bool& level) { return DoRead(level); }

 private:
  virtual GpioStatus DoRead(bool& level) = 0;
};

class DigitalOutput {
 public:
  DigitalOutput() = default;
  DigitalOutput(const DigitalOutput&) = delete;
  DigitalOutput& operator=(const DigitalOutput&) = delete;
  virtual ~DigitalOutput() = default;

  /// Drives the line to `level` (true = high). RT-safe per the backend contract.
  GpioStatus Set(bool level) { return DoSet(level); }

 private:
  virtual GpioStatus DoSet(bool level) = 0;
};

/// A line named on the command line: `CHIP:LINE`, e.g. "gpiochip0:17" or "/dev/gpiochip0:17".
struct LineSpec {
  std::string chip;   ///< chip name (gpiochipN) or device path (/dev/gpiochipN)
  unsigned line = 0;  ///< line offset on the chip
};

/// Parses `text` given to `option` (named in errors). Errors: missing ':', empty chip, a line that
/// is not a whole number in 0..65535. Non-RT.
std::expected<LineSpec, std::string> ParseLineSpec(std::string_view option, std::string_view text);

/// Which level asserts an input: "high" or "low".
std::expected<bool, std::string> ParseActiveLevel(std::string_view option, std::string_view text);

}  // namespace palpa::gpio
