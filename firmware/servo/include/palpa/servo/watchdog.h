// The servo loop's software watchdog: a helper thread that watches ServoLoop::tick_sequence()
// and, when one tick has run for longer than the timeout (the device layer stalled inside a
// transfer), latches the loop's fault (ServoLoop::RequestFault(kWatchdog)) and calls `on_trip`.
//
// What makes the force zero while the servo thread is stuck inside a device call is not this
// thread (it must not touch the device the servo thread is using) but the two mechanisms below
// it, which this one complements: (1) the device layer's own timeout — every transfer is bounded
// (libusb timeouts; FalconDevice latches a fault and writes zero torque when a reply is more than
// 2 ms late) — and (2) the tick line (--tick-gpio), which stops toggling during the stall so an
// external hardware watchdog (a retriggerable monostable on the amplifier enable) drops the
// motor power. When the stalled call returns, the latched fault makes the loop write zero force
// instead of a force computed from stale state, and Run ends with kWatchdogFault.
//
// Thread rules: Start/Stop on the start-up thread; the watchdog's own thread is SCHED_OTHER and
// polls every timeout/4 with a relative sleep (non-RT; wall-clock time by nature).
#pragma once

#include <atomic>
#include <cstdint>

#include "palpa/rt/thread.h"
#include "palpa/servo/servo_loop.h"

namespace palpa::servo {

class Watchdog {
 public:
  struct Config {
    std::int64_t timeout_ns = 50'000'000;  ///< a tick running longer than this trips, ns (> 0)
    /// Called on the watchdog thread at each trip with how long the tick had run, ns. May print.
    void (*on_trip)(void* context, std::int64_t stalled_ns) = nullptr;
    void* context = nullptr;
    int avoid_cpu = -1;  ///< keep off this CPU (the servo thread's --cpu); −1: any
  };

  Watchdog(ServoLoop& loop, const Config& config) : loop_(loop), config_(config) {}
  Watchdog(const Watchdog&) = delete;
  Watchdog& operator=(const Watchdog&) = delete;
  ~Watchdog() { Stop(); }

  /// Starts the thread. 0 or an errno value.
  int Start();
  /// Stops and joins it. Idempotent.
  void Stop();
  /// Trips so far (one per stalled tick).
  std::uint64_t trips() const { return trips_.load(std::memory_order_acquire); }

 private:
  static void Body(void* self);

  ServoLoop& loop_;
  Config config_;
  rt::HelperThread thread_;
  std::atomic<bool> quit_{false};
  std::atomic<std::uint64_t> trips_{0};
};

}  // namespace palpa::servo
