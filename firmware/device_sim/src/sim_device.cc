#include "palpa/device_sim/sim_device.h"

#include <cmath>
#include <utility>

namespace palpa::device_sim {
namespace {

// Tick time exactly as DoRead computes it, so TickCount() and kEnd agree to the last bit.
double TickTime(std::uint64_t n, double rate_hz) { return static_cast<double>(n) / rate_hz; }

}  // namespace

SimDevice::SimDevice(std::vector<trace::TraceSample> samples, double rate_hz)
    : samples_(std::move(samples)), rate_hz_(rate_hz) {
  if (samples_.empty() || !(rate_hz_ > 0) || !std::isfinite(rate_hz_)) return;  // TickCount() = 0: kEnd at once
  const double last = samples_.back().t_s;
  if (last < 0) return;
  // floor(last·rate) + 1, then corrected against the exact division DoRead uses.
  auto n = static_cast<std::uint64_t>(std::floor(last * rate_hz_));
  while (n > 0 && TickTime(n, rate_hz_) > last) --n;
  while (TickTime(n + 1, rate_hz_) <= last) ++n;
  tick_count_ = static_cast<std::size_t>(n + 1);
}

device::IoStatus SimDevice::DoRead(device::HipReading& out) {
  if (reads_ >= tick_count_) return device::IoStatus::kEnd;
  const double t = TickTime(reads_, rate_hz_);
  out.hip_m = trace::HipAt(samples_, t, cursor_);
  out.t_s = t;
  // Buttons are levels, not interpolated: those of the last sample at or before t.
  out.buttons = t >= samples_.back().t_s ? samples_.back().buttons : samples_[cursor_].buttons;
  ++reads_;
  return device::IoStatus::kOk;
}

device::IoStatus SimDevice::DoWrite(const std::array<double, 3>& force_n) {
  last_force_n_ = force_n;
  ++writes_;
  return device::IoStatus::kOk;
}

}  // namespace palpa::device_sim
