// A grip button read as a digital input: `palpad --estop button:N` makes the device's button N
// the e-stop (a dead-man input) without a GPIO chip. It reads the buttons of the device's last
// HIP reading; the servo loop reads its e-stop before the device, so a press reaches the force a
// tick after the device reported it (within one tick, the e-stop contract of docs/runtime.md).
// RT-safe: a load and a shift. Servo thread only.
#pragma once

#include "palpa/device/haptic_device.h"
#include "palpa/gpio/gpio.h"

namespace palpa::palpad {

class DeviceButtonInput final : public gpio::DigitalInput {
 public:
  /// `bit` in 0..7 (checked by the options). The device must outlive this input.
  DeviceButtonInput(const device::HapticDevice& device, int bit) : device_(device), bit_(bit) {}

 private:
  gpio::GpioStatus DoRead(bool& level) override {
    level = ((device_.last_buttons() >> bit_) & 1u) != 0;
    return gpio::GpioStatus::kOk;
  }

  const device::HapticDevice& device_;
  int bit_;
};

}  // namespace palpa::palpad
