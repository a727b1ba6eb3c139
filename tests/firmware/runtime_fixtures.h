// Test doubles for the runtime tests: a fake clock (simulated time: pacing, latency and overruns
// become exact) and a device that replays one HIP per tick, costs a scripted compute time per tick
// on the fake clock, and records every force written. Preallocated: the allocation-free test uses
// them inside its armed region.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "palpa/device/haptic_device.h"
#include "palpa/rt/clock.h"

namespace palpa::firmware_test {

class FakeClock final : public rt::Clock {
 public:
  explicit FakeClock(std::size_t max_sleeps = 1 << 16) { deadlines_.reserve(max_sleeps); }

  std::int64_t NowNs() override { return now_ns; }
  /// Jumps to the deadline (if it is ahead) plus the next scripted wake-up latency.
  void SleepUntilNs(std::int64_t deadline_ns, const std::atomic<bool>&) override {
    if (deadlines_.size() < deadlines_.capacity()) deadlines_.push_back(deadline_ns);
    if (deadline_ns > now_ns) now_ns = deadline_ns;
    const std::size_t n = sleeps_++;
    if (n < wake_latency_ns.size()) now_ns += wake_latency_ns[n];
  }

  std::int64_t now_ns = 1'000'000'000;        ///< starts at 1 s
  std::vector<std::int64_t> wake_latency_ns;  ///< latency added to the n-th sleep (0 beyond)
  const std::vector<std::int64_t>& deadlines() const { return deadlines_; }

 private:
  std::vector<std::int64_t> deadlines_;
  std::size_t sleeps_ = 0;
};

/// Replays hips[n] at the n-th read (kEnd after the last), advances the fake clock by cost_ns[n]
/// during that read (a tick's compute time), and records every write.
class TickDevice final : public device::HapticDevice {
 public:
  TickDevice(FakeClock& clock, std::vector<std::array<double, 3>> hips, std::vector<std::int64_t> cost_ns = {})
      : clock_(clock), hips_(std::move(hips)), cost_ns_(std::move(cost_ns)) {
    writes_.reserve(hips_.size() + 16);
  }
  const std::vector<std::array<double, 3>>& writes() const { return writes_; }
  std::uint64_t reads() const { return reads_; }

 private:
  device::IoStatus DoRead(device::HipReading& out) override {
    if (reads_ >= hips_.size()) return device::IoStatus::kEnd;
    if (reads_ < cost_ns_.size()) clock_.now_ns += cost_ns_[reads_];
    out.hip_m = hips_[reads_];
    out.t_s = static_cast<double>(reads_) * 1e-3;
    ++reads_;
    return device::IoStatus::kOk;
  }
  device::IoStatus DoWrite(const std::array<double, 3>& force_n) override {
    if (writes_.size() < writes_.capacity()) writes_.push_back(force_n);
    return device::IoStatus::kOk;
  }

  FakeClock& clock_;
  std::vector<std::array<double, 3>> hips_;
  std::vector<std::int64_t> cost_ns_;
  std::vector<std::array<double, 3>> writes_;
  std::size_t reads_ = 0;
};

}  // namespace palpa::firmware_test
