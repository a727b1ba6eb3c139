#include "palpa/rt/clock.h"

#include <cerrno>
#include <ctime>

namespace palpa::rt {
namespace {

class SystemMonotonicClock final : public Clock {
 public:
  std::int64_t NowNs() override {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::int64_t{ts.tv_sec} * kNsPerS + ts.tv_nsec;
  }

  void SleepUntilNs(std::int64_t deadline_ns, const std::atomic<bool>& stop) override {
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(deadline_ns / kNsPerS);
    ts.tv_nsec = static_cast<long>(deadline_ns % kNsPerS);
    // clock_nanosleep returns the error number (not -1/errno). EINTR: a signal (SIGINT/SIGTERM
    // sets the stop flag); any other error cannot happen for a valid timespec.
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
      if (stop.load(std::memory_order_acquire)) return;
    }
  }
};

// Constant-initialised: no guard variable (whose first use may lock) on the loop's path.
constinit SystemMonotonicClock g_clock;

}  // namespace

Clock& MonotonicClock() { return g_clock; }

void SleepForNs(std::int64_t ns) {
  const timespec ts{static_cast<time_t>(ns / kNsPerS), static_cast<long>(ns % kNsPerS)};
  nanosleep(&ts, nullptr);
}

}  // namespace palpa::rt
