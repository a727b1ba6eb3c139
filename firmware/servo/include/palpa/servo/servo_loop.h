// The servo loop: read the HIP, run the proxy (paper §3.3 eq. 9) and force (§3.4 eq. 10), write
// the force — once per tick, on one thread.
//
// Thread/RT rules: construct, inspect and report on any thread while the loop is not running
// (non-RT: the constructor allocates the log). Step() and Run() belong to the servo thread. Inside
// Step() there is no allocation, lock, exception or system call other than the device transfers
// and clock_gettime(CLOCK_MONOTONIC) (vDSO); tests/firmware/alloc_free_test.cc checks it. Run()
// adds clock_nanosleep in paced mode. The stop flag is the only thing another thread (or a signal
// handler) touches during a run.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <type_traits>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/device/haptic_device.h"
#include "palpa/proxy/proxy.h"
#include "palpa/sampler/trilinear.h"

namespace palpa::servo {

// Set from signal handlers and read by the loop: must be a plain lock-free atomic.
static_assert(std::atomic<bool>::is_always_lock_free);

/// One logged tick (the output CSV row). Device frame.
struct LogRow {
  double t_s = 0;                   ///< device time of the HIP sample, s
  std::array<double, 3> hip_m{};    ///< HIP as read, m
  std::array<double, 3> proxy_m{};  ///< proxy after the tick, m (the Q16.16 grid position converted)
  std::array<double, 3> force_n{};  ///< force written, N (the Q16.16 force converted exactly)
  bool contact = false;             ///< proxy held apart from the HIP by the surface
};
static_assert(std::is_trivially_copyable_v<LogRow>);

/// Counters the servo thread writes (house style §5); read them after the run.
struct ServoCounters {
  std::uint64_t ticks = 0;          ///< completed ticks (read, proxy, write)
  std::uint64_t contact_ticks = 0;  ///< ticks with contact
  std::uint64_t force_clamps = 0;   ///< ticks whose |f| hit max_force
  std::uint64_t device_errors = 0;  ///< failed reads/writes (each ends the run)
  std::uint64_t dropped_rows = 0;   ///< ticks not logged because the log was full
  std::uint64_t overruns = 0;       ///< paced mode: ticks that finished after the next deadline
  double max_force_n = 0;           ///< max |f| written, N
  double max_penetration_m = 0;     ///< max |X_p − X_h| in contact, m
};
static_assert(std::is_trivially_copyable_v<ServoCounters>);

/// Outcome of one Step().
enum class StepResult {
  kRunning,      ///< tick done, keep going
  kEnded,        ///< the device reported kEnd (replay over); zero force written
  kDeviceError,  ///< a transfer failed; counted, zero force written
};

/// Why Run() returned.
enum class RunEnd {
  kEnded,        ///< the device ran out (replay finished)
  kStopped,      ///< the stop flag was set (SIGINT/SIGTERM)
  kDeviceError,  ///< a device transfer failed
  kInvalidRate,  ///< paced mode with rate_hz outside [1, 10000]; nothing ran
};

class ServoLoop {
 public:
  /// `field` must be verified (blob::Verify) and its buffer must outlive the loop; `params` from
  /// proxy::MakeProxyParams for this field's voxel size; `device` outlives the loop; the log keeps
  /// the first `log_capacity` ticks (rows and durations), later ticks count as dropped. `stop` is
  /// polled once per tick. Non-RT: allocates and pre-faults the log.
  ServoLoop(const blob::FieldView& field, const proxy::ProxyParams& params, device::HapticDevice& device,
            std::size_t log_capacity, const std::atomic<bool>& stop);

  ServoLoop(const ServoLoop&) = delete;
  ServoLoop& operator=(const ServoLoop&) = delete;

  /// One tick: Read → GridFrame::ToGrid → proxy::ProxyTick → Q16.16 force → N → Write, then the
  /// row, counters and duration. On kEnd or an error: zero force written, nothing logged for a
  /// failed read. RT-safe: no allocation, lock, exception; syscalls only the device's and the clock.
  StepResult Step();

  /// Ticks until the device ends, a transfer fails or `stop` is set. fast: back to back
  /// (lockstep, deterministic output); paced: absolute deadlines start + n/rate_hz with
  /// clock_nanosleep(TIMER_ABSTIME) — a late tick counts an overrun and the loop skips to the next
  /// future deadline rather than running the missed ticks back to back. rate_hz in [1, 10000]
  /// (checked only when paced). Always ends by writing zero force. Servo thread; RT-safe as Step().
  RunEnd Run(bool fast, double rate_hz);

  const ServoCounters& counters() const { return counters_; }
  /// Logged rows, in tick order (at most log_capacity).
  std::span<const LogRow> rows() const { return {rows_.data(), row_count_}; }
  /// Duration of each logged tick, ns, from before Read to after Write.
  std::span<const std::int64_t> tick_ns() const { return {tick_ns_.data(), row_count_}; }
  const proxy::ProxyState& proxy_state() const { return state_; }
  const proxy::GridFrame& frame() const { return frame_; }

 private:
  void WriteZeroForce();

  sampler::TrilinearSampler sampler_;
  proxy::ProxyParams params_;
  proxy::GridFrame frame_;
  proxy::ProxyState state_;
  device::HapticDevice& device_;
  const std::atomic<bool>& stop_;
  std::vector<LogRow> rows_;           // size fixed at construction; never grows
  std::vector<std::int64_t> tick_ns_;  // same size as rows_
  std::size_t row_count_ = 0;
  ServoCounters counters_;
};

}  // namespace palpa::servo
