// Simulated GPIO lines for tests and for runs without a GPIO chip (house style §8: mocks that
// record). Both read an injected clock (palpa/rt/clock.h), so a test on simulated time gets exact
// timestamps.
//
// SimOutput records every Set as {t_ns, level} in a fixed-capacity log (later sets are counted as
// dropped, never allocated). SimInput plays a script of {t_ns, level} steps: the level at time t is
// that of the last step with t_ns ≤ t (before the first step: `initial`); a test may also force a
// level from another thread (Force). Either can be told to fail, to exercise the error paths.
//
// Thread rules: Read/Set on one thread (the servo thread). Force/ClearForce/set_fail may be called
// from any thread (atomics). log()/reads() after the run. RT-safe: no allocation, lock or system
// call in Read/Set beyond the clock's NowNs. Construction is non-RT.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "palpa/gpio/gpio.h"
#include "palpa/rt/clock.h"

namespace palpa::gpio_sim {

/// One recorded or scripted level change.
struct LevelSample {
  std::int64_t t_ns = 0;  ///< clock time, ns
  bool level = false;     ///< physical level (true = high)
  friend bool operator==(const LevelSample&, const LevelSample&) = default;
};

class SimOutput final : public gpio::DigitalOutput {
 public:
  /// Keeps the first `capacity` sets. Non-RT (allocates and touches the log).
  SimOutput(rt::Clock& clock, std::size_t capacity);

  std::span<const LevelSample> log() const { return {log_.data(), count_}; }
  std::uint64_t sets() const { return sets_; }
  std::uint64_t dropped() const { return sets_ - count_; }
  bool level() const { return level_; }
  /// While true, Set fails (kError) and records nothing.
  void set_fail(bool fail) { fail_.store(fail, std::memory_order_relaxed); }

 private:
  gpio::GpioStatus DoSet(bool level) override;

  rt::Clock& clock_;
  std::vector<LevelSample> log_;
  std::size_t count_ = 0;
  std::uint64_t sets_ = 0;
  bool level_ = false;
  std::atomic<bool> fail_{false};
};

class SimInput final : public gpio::DigitalInput {
 public:
  /// `script`: level steps in non-decreasing time. Non-RT.
  SimInput(rt::Clock& clock, std::vector<LevelSample> script, bool initial = false);

  /// Overrides the script with `level` until ClearForce. Any thread.
  void Force(bool level) { forced_.store(level ? 1 : 0, std::memory_order_release); }
  void ClearForce() { forced_.store(-1, std::memory_order_release); }
  /// While true, Read fails (kError).
  void set_fail(bool fail) { fail_.store(fail, std::memory_order_relaxed); }
  std::uint64_t reads() const { return reads_; }

 private:
  gpio::GpioStatus DoRead(bool& level) override;

  rt::Clock& clock_;
  std::vector<LevelSample> script_;
  bool initial_;
  std::size_t cursor_ = 0;  // script index of the next step (time only moves forward)
  std::uint64_t reads_ = 0;
  std::atomic<int> forced_{-1};
  std::atomic<bool> fail_{false};
};

}  // namespace palpa::gpio_sim
