#include "palpa/gpio_sim/sim_gpio.h"

#include <utility>

namespace palpa::gpio_sim {

SimOutput::SimOutput(rt::Clock& clock, std::size_t capacity) : clock_(clock), log_(capacity) {}

gpio::GpioStatus SimOutput::DoSet(bool level) {
  if (fail_.load(std::memory_order_relaxed)) return gpio::GpioStatus::kError;
  level_ = level;
  if (count_ < log_.size()) log_[count_++] = {clock_.NowNs(), level};
  ++sets_;
  return gpio::GpioStatus::kOk;
}

SimInput::SimInput(rt::Clock& clock, std::vector<LevelSample> script, bool initial)
    : clock_(clock), script_(std::move(script)), initial_(initial) {}

gpio::GpioStatus SimInput::DoRead(bool& level) {
  ++reads_;
  if (fail_.load(std::memory_order_relaxed)) return gpio::GpioStatus::kError;
  if (const int f = forced_.load(std::memory_order_acquire); f >= 0) {
    level = f == 1;
    return gpio::GpioStatus::kOk;
  }
  const std::int64_t now = clock_.NowNs();
  while (cursor_ < script_.size() && script_[cursor_].t_ns <= now) ++cursor_;
  level = cursor_ == 0 ? initial_ : script_[cursor_ - 1].level;
  return gpio::GpioStatus::kOk;
}

}  // namespace palpa::gpio_sim
