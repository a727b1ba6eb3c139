#include "palpa/servo/telemetry_drain.h"

#include <cstdio>
#include <ctime>
#include <span>

#include "palpa/io/atomic_file.h"
#include "palpa/servo/report.h"

namespace palpa::servo {
namespace {

std::int64_t MonotonicNs() { return rt::MonotonicClock().NowNs(); }
using rt::SleepForNs;

constexpr int kBatch = 256;  // samples per pass before looking at the clock again

}  // namespace

int TelemetryDrain::Start() {
  if (config_.csv != nullptr && !WriteCsvHeader(config_.csv)) csv_failed_.store(true, std::memory_order_release);
  quit_.store(false, std::memory_order_release);
  return thread_.Start("palpad-drain", &TelemetryDrain::Body, this, config_.avoid_cpu);
}

void TelemetryDrain::Stop(const char* final_state) {
  if (stopped_) return;
  stopped_ = true;
  quit_.store(true, std::memory_order_release);
  thread_.Join();
  while (DrainOnce()) {
  }
  if (config_.csv != nullptr && std::fflush(config_.csv) != 0) csv_failed_.store(true, std::memory_order_release);
  (void)WriteStatus(final_state);
}

DrainStatus TelemetryDrain::LiveStatus() const {
  const std::lock_guard<std::mutex> lock(live_mutex_);
  return live_;
}

bool TelemetryDrain::DrainOnce() {
  TelemetrySample s;
  int n = 0;
  bool was_estop = status_.estop;
  while (n < kBatch && ring_.Pop(s)) {
    ++n;
    if (config_.sink != nullptr) config_.sink->Consume(s);
    if (config_.csv != nullptr && !csv_failed_.load(std::memory_order_relaxed)) {
      if (WriteCsvRow(config_.csv, s.row)) {
        rows_written_.fetch_add(1, std::memory_order_acq_rel);
      } else {
        csv_failed_.store(true, std::memory_order_release);  // keep consuming: the loop must never wait on us
      }
    }
    DrainStatus& st = status_;
    ++st.samples;
    st.last_tick = s.tick;
    st.t_s = s.row.t_s;
    st.force_n = s.row.force_n;
    st.contact_ticks += s.row.contact ? 1 : 0;
    st.estop = (s.flags & kFlagEstop) != 0;
    st.estop_ticks += st.estop ? 1 : 0;
    st.overruns += (s.flags & kFlagOverrun) != 0 ? 1 : 0;
    if (s.wake_latency_ns > st.max_wake_latency_ns) st.max_wake_latency_ns = s.wake_latency_ns;
    if (s.compute_ns > st.max_compute_ns) st.max_compute_ns = s.compute_ns;
    if (st.estop && !was_estop) ++st.estop_events;
    was_estop = st.estop;
    st.hip_m = s.row.hip_m;
    st.proxy_m = s.row.proxy_m;
    st.contact = s.row.contact;
    st.swap_ramp = (s.flags & kFlagSwapRamp) != 0;
    st.force_clamps += (s.flags & kFlagClamped) != 0 ? 1 : 0;
    st.field_swaps += (s.flags & kFlagSwap) != 0 ? 1 : 0;
  }
  if (n > 0) {
    const std::lock_guard<std::mutex> lock(live_mutex_);
    live_ = status_;
  }
  return n > 0;
}

void TelemetryDrain::Body(void* self) {
  auto& d = *static_cast<TelemetryDrain*>(self);
  std::int64_t next_status = MonotonicNs();
  while (!d.quit_.load(std::memory_order_acquire)) {
    const bool took = d.DrainOnce();
    if (!d.config_.status_path.empty() && MonotonicNs() >= next_status) {
      (void)d.WriteStatus("running");
      next_status += d.config_.status_period_ns;
    }
    if (!took) SleepForNs(d.config_.poll_ns);
  }
}

std::string TelemetryDrain::StatusJson(const char* state) const {
  const DrainStatus& s = status_;
  char buf[768];
  std::snprintf(buf, sizeof buf,
                "\"rate_hz\": %.17g, \"fast\": %s, \"samples\": %llu, \"dropped\": %llu, \"last_tick\": %llu, "
                "\"t_s\": %.12g, \"contact_ticks\": %llu, \"estop\": %s, \"estop_ticks\": %llu, \"overruns\": %llu, "
                "\"max_wake_latency_ns\": %lld, \"max_compute_ns\": %lld, \"force_n\": [%.9g, %.9g, %.9g], "
                "\"csv_error\": %s}\n",
                config_.rate_hz, config_.fast ? "true" : "false", static_cast<unsigned long long>(s.samples),
                static_cast<unsigned long long>(ring_.dropped()), static_cast<unsigned long long>(s.last_tick), s.t_s,
                static_cast<unsigned long long>(s.contact_ticks), s.estop ? "true" : "false",
                static_cast<unsigned long long>(s.estop_ticks), static_cast<unsigned long long>(s.overruns),
                static_cast<long long>(s.max_wake_latency_ns), static_cast<long long>(s.max_compute_ns), s.force_n[0],
                s.force_n[1], s.force_n[2], csv_failed() ? "true" : "false");
  return "{\"state\": " + JsonString(state) + ", \"realtime\": " + (config_.realtime ? "true" : "false") +
         ", \"realtime_requested\": " + (config_.realtime_requested ? "true" : "false") +
         ", \"rt_refused\": " + JsonString(config_.rt_refused) + ", " + buf;
}

bool TelemetryDrain::WriteStatus(const char* state) {
  if (config_.status_path.empty()) return true;
  const std::string json = StatusJson(state);
  // The target is checked on every write (rename() would replace a device or FIFO put there
  // meanwhile), the temporary registered for the fatal-signal path. Not fsync'ed: a live view.
  // A failed update is retried next period.
  return io::WriteFileAtomically(config_.status_path, std::as_bytes(std::span(json)), {.durable = false}).has_value();
}

}  // namespace palpa::servo
