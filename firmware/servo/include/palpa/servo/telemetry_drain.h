// The non-RT side of the telemetry ring: a helper thread that drains ServoLoop's SPSC ring to the
// output CSV as the run goes (so long runs need no log in memory) and keeps a live status, written
// as JSON once a second (house style §3b, §5).
//
// Status file (--status PATH), replaced atomically (io::WriteFileAtomically: temporary file +
// rename; no fsync, it is a live view — put it on tmpfs, e.g. /run/palpa/status.json):
//   {"state": "running"|<how the run ended>, "realtime": bool, "realtime_requested": bool,
//    "rt_refused": "...", "rate_hz": R, "fast": bool, "samples": N, "dropped": N, "last_tick": N,
//    "t_s": T, "contact_ticks": N, "estop": bool, "estop_ticks": N, "overruns": N,
//    "max_wake_latency_ns": N, "max_compute_ns": N, "force_n": [x, y, z], "csv_error": bool}
// Everything in it comes from the samples (and the ring's drop counter): the RT side publishes
// nothing else.
//
// Thread rules: Start/Stop on the start-up thread; between them the drain thread is the ring's
// only consumer. Non-RT (stdio, file system).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>
#include <utility>

#include "palpa/rt/thread.h"
#include "palpa/servo/servo_loop.h"

namespace palpa::servo {

/// A further consumer of every drained sample, called on the drain thread in tick order (e.g.
/// palpad --record, firmware/palpad/src/recorder.h). Non-RT: it may do file I/O.
class TelemetrySink {
 public:
  virtual ~TelemetrySink() = default;
  virtual void Consume(const TelemetrySample& sample) = 0;
};

struct DrainConfig {
  std::FILE* csv = nullptr;       ///< rows in WriteCsv's format (header at Start); nullptr: rows are discarded
  TelemetrySink* sink = nullptr;  ///< also gets every sample (palpad --record); nullptr: none
  std::string status_path;        ///< empty: no status file
  std::int64_t status_period_ns = 1'000'000'000;
  std::int64_t poll_ns = 5'000'000;  ///< sleep when the ring is empty (5 ms: 50 samples at 10 kHz)
  int avoid_cpu = -1;                ///< keep off this CPU (the servo thread's --cpu); −1: any
  // Copied into the status as is.
  double rate_hz = 0;
  bool fast = false;
  bool realtime_requested = false;
  bool realtime = false;
  std::string rt_refused;
};

/// What the drain has seen so far.
struct DrainStatus {
  std::uint64_t samples = 0;
  std::uint64_t last_tick = 0;
  double t_s = 0;
  std::uint64_t contact_ticks = 0;
  std::uint64_t estop_ticks = 0;
  bool estop = false;
  std::uint64_t overruns = 0;
  std::int64_t max_wake_latency_ns = 0;
  std::int64_t max_compute_ns = 0;
  std::array<double, 3> force_n{};
  // The latest sample and counts derived from the flags (palpa status, issue 7).
  std::array<double, 3> hip_m{};
  std::array<double, 3> proxy_m{};
  bool contact = false;
  bool swap_ramp = false;
  std::uint64_t force_clamps = 0;  ///< samples flagged kFlagClamped
  std::uint64_t estop_events = 0;  ///< released → asserted transitions seen in the samples
  std::uint64_t field_swaps = 0;   ///< samples flagged kFlagSwap
};

class TelemetryDrain {
 public:
  TelemetryDrain(TelemetryRing& ring, DrainConfig config) : ring_(ring), config_(std::move(config)) {}
  TelemetryDrain(const TelemetryDrain&) = delete;
  TelemetryDrain& operator=(const TelemetryDrain&) = delete;
  ~TelemetryDrain() { Stop("stopped"); }

  /// Writes the CSV header and starts the thread. 0 or an errno value (then nothing drains).
  int Start();
  /// Stops the thread after it drained everything queued, then writes the final status with
  /// `final_state` (e.g. "ended"). Idempotent. After Stop, status() is exact.
  void Stop(const char* final_state);

  /// The CSV could not be written (the drain kept consuming, so the loop never blocked).
  bool csv_failed() const { return csv_failed_.load(std::memory_order_acquire); }
  std::uint64_t rows_written() const { return rows_written_.load(std::memory_order_acquire); }
  /// After Stop.
  const DrainStatus& status() const { return status_; }
  /// Any thread, while running: a copy of the status as of the last drained batch (under a mutex
  /// only the drain thread and readers take; the loop never sees it). Non-RT.
  DrainStatus LiveStatus() const;
  /// The status JSON with `state`.
  std::string StatusJson(const char* state) const;
  /// Writes the status file now (before Start: to check the path). False if it could not be
  /// written; true also when no status path is configured.
  bool WriteStatus(const char* state);

 private:
  static void Body(void* self);
  bool DrainOnce();  // true if it took anything

  TelemetryRing& ring_;
  DrainConfig config_;
  rt::HelperThread thread_;
  std::atomic<bool> quit_{false};
  std::atomic<bool> csv_failed_{false};
  std::atomic<std::uint64_t> rows_written_{0};
  DrainStatus status_;
  mutable std::mutex live_mutex_;
  DrainStatus live_;
  bool stopped_ = false;
};

}  // namespace palpa::servo
