#include "palpa/servo/watchdog.h"

#include <ctime>

namespace palpa::servo {
namespace {

std::int64_t MonotonicNs() { return rt::MonotonicClock().NowNs(); }
using rt::SleepForNs;

}  // namespace

int Watchdog::Start() {
  quit_.store(false, std::memory_order_release);
  return thread_.Start("palpad-watchdog", &Watchdog::Body, this, config_.avoid_cpu);
}

void Watchdog::Stop() {
  quit_.store(true, std::memory_order_release);
  thread_.Join();
}

void Watchdog::Body(void* self) {
  auto& w = *static_cast<Watchdog*>(self);
  const std::int64_t timeout = w.config_.timeout_ns > 0 ? w.config_.timeout_ns : 1;
  const std::int64_t poll = timeout / 4 > 0 ? timeout / 4 : 1;
  std::uint64_t seen_seq = w.loop_.tick_sequence();
  std::int64_t seen_at = MonotonicNs();
  std::uint64_t tripped_seq = ~std::uint64_t{0};
  while (!w.quit_.load(std::memory_order_acquire)) {
    SleepForNs(poll);
    const std::uint64_t seq = w.loop_.tick_sequence();
    const std::int64_t now = MonotonicNs();
    if (seq != seen_seq) {
      seen_seq = seq;
      seen_at = now;
      continue;
    }
    // The same odd sequence number for longer than the timeout: one tick is stuck.
    if ((seq & 1u) != 0 && now - seen_at > timeout && seq != tripped_seq) {
      tripped_seq = seq;
      w.loop_.RequestFault(FaultCause::kWatchdog);
      w.trips_.fetch_add(1, std::memory_order_acq_rel);
      if (w.config_.on_trip != nullptr) w.config_.on_trip(w.config_.context, now - seen_at);
    }
  }
}

}  // namespace palpa::servo
