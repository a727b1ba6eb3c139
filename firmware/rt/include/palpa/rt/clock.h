// The servo loop's time source, injectable so that pacing, overrun and fault logic can be tested
// on simulated time (a 1 kHz loop does not keep real time under qemu-user or on a loaded CI box;
// docs/cross-rt.md §1-2).
#pragma once

#include <atomic>
#include <cstdint>

namespace palpa::rt {

inline constexpr std::int64_t kNsPerS = 1'000'000'000;

class Clock {
 public:
  Clock() = default;
  Clock(const Clock&) = delete;
  Clock& operator=(const Clock&) = delete;
  virtual ~Clock() = default;

  /// Monotonic time, ns. RT-safe for every implementation (no allocation or lock; the system
  /// clock reads CLOCK_MONOTONIC through the vDSO, without a system call).
  virtual std::int64_t NowNs() = 0;

  /// Sleeps until `deadline_ns` (absolute, the NowNs() time base) or until `stop` is set (a
  /// signal interrupts the sleep; the flag is then checked). RT-safe: the system clock's only
  /// system call is clock_nanosleep.
  virtual void SleepUntilNs(std::int64_t deadline_ns, const std::atomic<bool>& stop) = 0;
};

/// CLOCK_MONOTONIC with clock_nanosleep(TIMER_ABSTIME): absolute deadlines, so sleep overshoot
/// does not accumulate. Thread-safe (stateless).
Clock& MonotonicClock();

/// Sleeps at least `ns` nanoseconds on CLOCK_MONOTONIC (relative): the polls and naps of the
/// helper threads (drain, watchdog, listener), never the paced loop. Non-RT.
void SleepForNs(std::int64_t ns);

}  // namespace palpa::rt
