// After the run: the output CSV and the summary. Non-RT (allocates, does file I/O); call only
// while the loop is not running.
#pragma once

#include <cstdint>
#include <cstdio>
#include <expected>
#include <span>
#include <string>
#include <string_view>
#include <utility>

#include "palpa/servo/servo_loop.h"

namespace palpa::servo {

/// Output CSV column line, header and row writers: the run record's (palpa/record/run_record.h).
using record::kCsvHeader;
using record::WriteCsvHeader;
using record::WriteCsvRow;

/// Writes the header and `rows` to `out` (record::WriteCsvHeader, record::WriteCsvRow). Same rows
/// → same bytes. False on an I/O error.
bool WriteCsv(std::FILE* out, std::span<const LogRow> rows);

/// WriteCsv through an io::AtomicFile (palpa/io/atomic_file.h): the target is replaced whole or
/// not at all. Error: a sentence naming the path.
std::expected<void, std::string> WriteCsvAtomic(const std::string& path, std::span<const LogRow> rows);

/// Percentiles of one histogram, ns (nearest rank, bin lower edge; record::PercentileOfBins).
struct LatencyFigures {
  std::uint64_t count = 0;
  std::int64_t min_ns = 0;
  std::int64_t p50_ns = 0;
  std::int64_t p99_ns = 0;
  std::int64_t p999_ns = 0;
  std::int64_t max_ns = 0;  ///< exact
  double mean_ns = 0;
};

template <typename Histogram>
LatencyFigures FiguresOf(const Histogram& h) {
  return {h.count(),  h.min_ns(), h.PercentileNs(0.5), h.PercentileNs(0.99), h.PercentileNs(0.999),
          h.max_ns(), h.mean_ns()};
}

/// The run in numbers, for people (SummaryText) and scripts (SummaryJson).
struct ServoSummary {
  std::uint64_t ticks = 0;
  std::uint64_t contact_ticks = 0;
  double max_force_n = 0;
  double max_penetration_mm = 0;
  std::int64_t median_tick_ns = 0;  ///< compute time p50 (10 ns bins); 0 if no tick
  std::int64_t p99_tick_ns = 0;     ///< compute time p99 (10 ns bins); 0 if no tick
  std::uint64_t force_clamps = 0;
  std::uint64_t device_errors = 0;
  std::uint64_t overruns = 0;
  std::uint64_t max_consecutive_overruns = 0;
  std::uint64_t dropped_rows = 0;  ///< telemetry samples the ring dropped
  std::uint64_t estop_events = 0;
  std::uint64_t estop_ticks = 0;
  std::uint64_t gpio_errors = 0;
  std::uint64_t watchdog_trips = 0;
  LatencyFigures wake;     ///< wake-up latency (paced runs; count 0 in fast mode)
  LatencyFigures compute;  ///< compute time per tick
  std::string end;         ///< RunEndName, e.g. "ended"; empty if not set
  std::string fault;       ///< FaultCauseName when a fault latched, else empty
  double rate_hz = 0;
  bool fast = false;
  /// Real-time set-up: requested for paced runs; `realtime` false with `rt_refused` naming the
  /// refused steps when the system refused any (rt::RtSetup::Refused()).
  bool realtime_requested = false;
  bool realtime = false;
  std::string rt_refused;
};

/// Counters and histograms of `loop`; the caller fills end, watchdog_trips and the RT fields.
ServoSummary Summarize(const ServoLoop& loop, bool fast, double rate_hz);

/// `key: value` lines: ticks, ticks in contact, max force (N), max penetration (mm),
/// median tick (ns), p99 tick (ns), force clamps, device errors, overruns (and the longest run of
/// consecutive ones), dropped samples, e-stops, GPIO errors, watchdog trips, wake-up latency and
/// compute time (p50/p99/p99.9/max, µs), mode (fast | paced at N Hz), real-time (yes | NO, with
/// the refused steps | not requested), end (and fault).
std::string SummaryText(const ServoSummary& s);

/// One JSON object with the same figures: ticks, contact_ticks, max_force_n, max_penetration_mm,
/// median_tick_ns, p99_tick_ns, force_clamps, device_errors, overruns, max_consecutive_overruns,
/// dropped_rows, estop_events, estop_ticks, gpio_errors, watchdog_trips, wake_latency_ns {count,
/// min, p50, p99, p999, max}, compute_ns {…}, rate_hz, fast, realtime_requested, realtime,
/// rt_refused, end, fault.
std::string SummaryJson(const ServoSummary& s);

/// The wake-up latency histogram file (record::FormatLatencyHistogram: cyclictest's histogram file
/// layout) with palpad's own "# palpad <key>: <value>" lines: max_ns, compute_ns (p50 p99 p999
/// max), overruns, max_consecutive_overruns, dropped_rows, rate_hz, realtime, rt_refused. One
/// parser reads palpad's and cyclictest's files (record::ReadLatencyHistogram, palpa bench latency).
std::string LatencyHistogramText(const WakeLatencyHistogram& h, const ServoSummary& s);

/// `s` as a JSON string literal (quotes, backslashes and control characters escaped).
std::string JsonString(std::string_view s);

}  // namespace palpa::servo
