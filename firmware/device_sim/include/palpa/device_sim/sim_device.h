// SimDevice: a HapticDevice that replays a HIP trace (palpa/trace/trace.h) instead of a Falcon.
// Lockstep replay: the n-th Read (n = 0, 1, …) returns the HIP at t = n / rate_hz, linearly
// interpolated between samples (before the first sample: the first sample). It answers kEnd once
// t passes the trace's last time, so a replay has exactly TickCount() ticks whatever the pacing.
// Writes are recorded (last force, count) for tests and the summary.
// RT-safe: Read/Write allocate nothing (trace::HipAt with a cursor, O(1) amortised); construction
// is non-RT. Thread rules as HapticDevice: one servo thread.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "palpa/device/haptic_device.h"
#include "palpa/device/limits.h"
#include "palpa/trace/trace.h"

namespace palpa::device_sim {

/// A replay pushes on nothing, so its limits are the proxy's own bounds (proxy::MakeProxyParams:
/// k ≤ 1e5 N/m, |f| ≤ 100 N); a non-finite, negative or zero k or force is refused all the same.
inline constexpr device::DeviceLimits kSimLimits = {"the simulated device", 1e5, 100.0,
                                                    "the proxy's bounds, proxy::MakeProxyParams"};

class SimDevice final : public device::HapticDevice {
 public:
  /// Takes the parsed trace (≥ 2 samples, strictly increasing times, as trace::ReadTrace returns)
  /// and the tick rate, Hz (> 0, finite). Non-RT (owns the samples; no allocation afterwards).
  SimDevice(std::vector<trace::TraceSample> samples, double rate_hz);

  /// Reads that answer kOk before kEnd: the number of n ≥ 0 with n / rate_hz ≤ last time.
  /// The servo loop sizes its log with it. Non-RT (constant after construction).
  std::size_t TickCount() const { return tick_count_; }

  /// Last force written, N (zero before any write).
  const std::array<double, 3>& last_force_n() const { return last_force_n_; }
  /// Reads answered kOk so far (= the index of the next tick).
  std::uint64_t reads() const { return reads_; }
  /// Writes accepted so far.
  std::uint64_t writes() const { return writes_; }

 private:
  device::IoStatus DoRead(device::HipReading& out) override;
  device::IoStatus DoWrite(const std::array<double, 3>& force_n) override;

  std::vector<trace::TraceSample> samples_;
  double rate_hz_;
  std::size_t tick_count_ = 0;
  std::size_t cursor_ = 0;  // trace::HipAt's hint: monotonic replay costs O(1) per read
  std::uint64_t reads_ = 0;
  std::uint64_t writes_ = 0;
  std::array<double, 3> last_force_n_{};
};

}  // namespace palpa::device_sim
