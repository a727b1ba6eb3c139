#include "palpa/servo/report.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdarg>
#include <cstring>
#include <utility>
#include <vector>

#include "palpa/io/atomic_file.h"
#include "palpa/record/latency_histogram.h"

namespace palpa::servo {
namespace {

[[gnu::format(printf, 1, 2)]] std::string Printf(const char* fmt, ...) {
  char buf[512];
  va_list args;
  va_start(args, fmt);
  const int n = std::vsnprintf(buf, sizeof buf, fmt, args);
  va_end(args);
  if (n < 0) return {};
  return std::string(buf, std::min(static_cast<std::size_t>(n), sizeof buf - 1));
}

std::string ErrnoMessage(const char* what, const std::string& path) {
  return Printf("%s %s: %s", what, path.c_str(), std::strerror(errno));
}

}  // namespace

bool WriteCsv(std::FILE* out, std::span<const LogRow> rows) {
  if (!WriteCsvHeader(out)) return false;
  for (const LogRow& r : rows)
    if (!WriteCsvRow(out, r)) return false;
  return std::ferror(out) == 0;
}

std::expected<void, std::string> WriteCsvAtomic(const std::string& path, std::span<const LogRow> rows) {
  auto file = io::AtomicFile::Create(path);
  if (!file) return std::unexpected(std::move(file.error()));
  if (!WriteCsv(file->file(), rows)) return std::unexpected(ErrnoMessage("cannot write", path));
  return file->Commit();
}

ServoSummary Summarize(const ServoLoop& loop, bool fast, double rate_hz) {
  const ServoCounters& c = loop.counters();
  ServoSummary s;
  s.ticks = c.ticks;
  s.contact_ticks = c.contact_ticks;
  s.max_force_n = c.max_force_n;
  s.max_penetration_mm = c.max_penetration_m * 1e3;
  s.wake = FiguresOf(loop.wake_latency());
  s.compute = FiguresOf(loop.compute_time());
  s.median_tick_ns = s.compute.p50_ns;
  s.p99_tick_ns = s.compute.p99_ns;
  s.force_clamps = c.force_clamps;
  s.device_errors = c.device_errors;
  s.overruns = c.overruns;
  s.max_consecutive_overruns = c.max_consecutive_overruns;
  s.dropped_rows = c.dropped_rows;
  s.estop_events = c.estop_events;
  s.estop_ticks = c.estop_ticks;
  s.gpio_errors = c.gpio_errors;
  if (loop.fault() != FaultCause::kNone) s.fault = FaultCauseName(loop.fault());
  s.rate_hz = rate_hz;
  s.fast = fast;
  return s;
}

namespace {

std::string Us(std::int64_t ns) { return Printf("%.1f", static_cast<double>(ns) / 1e3); }

std::string FiguresText(const char* name, const LatencyFigures& f) {
  if (f.count == 0) return Printf("%s (us): not measured\n", name);
  return Printf("%s (us): p50 %s, p99 %s, p99.9 %s, max %s (%llu ticks)\n", name, Us(f.p50_ns).c_str(),
                Us(f.p99_ns).c_str(), Us(f.p999_ns).c_str(), Us(f.max_ns).c_str(),
                static_cast<unsigned long long>(f.count));
}

std::string FiguresJson(const LatencyFigures& f) {
  return Printf("{\"count\": %llu, \"min\": %lld, \"p50\": %lld, \"p99\": %lld, \"p999\": %lld, \"max\": %lld}",
                static_cast<unsigned long long>(f.count), static_cast<long long>(f.min_ns),
                static_cast<long long>(f.p50_ns), static_cast<long long>(f.p99_ns), static_cast<long long>(f.p999_ns),
                static_cast<long long>(f.max_ns));
}

}  // namespace

std::string LatencyHistogramText(const WakeLatencyHistogram& h, const ServoSummary& s) {
  static_assert(WakeLatencyHistogram::kBinWidthNs == 1000, "the histogram file has 1 us bins");
  const record::LatencyTotals totals{h.count(), h.overflow(), h.min_ns(), h.mean_ns(), h.max_ns()};
  const record::PalpadLine lines[] = {
      {"compute_ns",
       Printf("%lld %lld %lld %lld", static_cast<long long>(s.compute.p50_ns), static_cast<long long>(s.compute.p99_ns),
              static_cast<long long>(s.compute.p999_ns), static_cast<long long>(s.compute.max_ns))},
      {"overruns", std::to_string(s.overruns)},
      {"max_consecutive_overruns", std::to_string(s.max_consecutive_overruns)},
      {"dropped_rows", std::to_string(s.dropped_rows)},
      {"rate_hz", Printf("%.17g", s.rate_hz)},
      {"realtime", !s.realtime_requested ? "not requested"
                   : s.realtime          ? "yes"
                                         : "no"},
      {"rt_refused", s.rt_refused}};
  return record::FormatLatencyHistogram(h.bins(), totals, lines);
}

std::string JsonString(std::string_view s) {
  std::string out = "\"";
  for (const char ch : s) {
    const auto u = static_cast<unsigned char>(ch);
    if (ch == '"' || ch == '\\') {
      out += '\\';
      out += ch;
    } else if (u < 0x20) {
      out += Printf("\\u%04x", u);
    } else {
      out += ch;
    }
  }
  out += '"';
  return out;
}

std::string SummaryText(const ServoSummary& s) {
  std::string out;
  out += Printf("ticks: %llu\n", static_cast<unsigned long long>(s.ticks));
  out += Printf("ticks in contact: %llu\n", static_cast<unsigned long long>(s.contact_ticks));
  out += Printf("max force (N): %.4f\n", s.max_force_n);
  out += Printf("max penetration (mm): %.4f\n", s.max_penetration_mm);
  out += Printf("median tick (ns): %lld\n", static_cast<long long>(s.median_tick_ns));
  out += Printf("p99 tick (ns): %lld\n", static_cast<long long>(s.p99_tick_ns));
  out += Printf("force clamps: %llu\n", static_cast<unsigned long long>(s.force_clamps));
  out += Printf("device errors: %llu\n", static_cast<unsigned long long>(s.device_errors));
  out += Printf("overruns: %llu (longest run %llu)\n", static_cast<unsigned long long>(s.overruns),
                static_cast<unsigned long long>(s.max_consecutive_overruns));
  out += Printf("dropped rows: %llu\n", static_cast<unsigned long long>(s.dropped_rows));
  out += Printf("e-stops: %llu (%llu ticks at zero force)\n", static_cast<unsigned long long>(s.estop_events),
                static_cast<unsigned long long>(s.estop_ticks));
  out += Printf("gpio errors: %llu\n", static_cast<unsigned long long>(s.gpio_errors));
  out += Printf("watchdog trips: %llu\n", static_cast<unsigned long long>(s.watchdog_trips));
  out += FiguresText("wake-up latency", s.wake);
  out += FiguresText("compute time", s.compute);
  out += s.fast ? std::string("mode: fast\n") : Printf("mode: paced at %g Hz\n", s.rate_hz);
  if (!s.realtime_requested) {
    out += "real-time: not requested\n";
  } else if (s.realtime) {
    out += "real-time: yes\n";
  } else {
    out += "real-time: NO (refused: " + s.rt_refused + ")\n";
  }
  if (!s.end.empty()) out += "end: " + s.end + (s.fault.empty() ? "" : " (fault: " + s.fault + ")") + "\n";
  return out;
}

std::string SummaryJson(const ServoSummary& s) {
  // %.17g round-trips a double; the values are finite by construction.
  std::string out = Printf(
      "{\"ticks\": %llu, \"contact_ticks\": %llu, \"max_force_n\": %.17g, \"max_penetration_mm\": %.17g, "
      "\"median_tick_ns\": %lld, \"p99_tick_ns\": %lld, \"force_clamps\": %llu, \"device_errors\": %llu, "
      "\"overruns\": %llu, \"max_consecutive_overruns\": %llu, \"dropped_rows\": %llu, \"estop_events\": %llu, "
      "\"estop_ticks\": %llu, \"gpio_errors\": %llu, \"watchdog_trips\": %llu, ",
      static_cast<unsigned long long>(s.ticks), static_cast<unsigned long long>(s.contact_ticks), s.max_force_n,
      s.max_penetration_mm, static_cast<long long>(s.median_tick_ns), static_cast<long long>(s.p99_tick_ns),
      static_cast<unsigned long long>(s.force_clamps), static_cast<unsigned long long>(s.device_errors),
      static_cast<unsigned long long>(s.overruns), static_cast<unsigned long long>(s.max_consecutive_overruns),
      static_cast<unsigned long long>(s.dropped_rows), static_cast<unsigned long long>(s.estop_events),
      static_cast<unsigned long long>(s.estop_ticks), static_cast<unsigned long long>(s.gpio_errors),
      static_cast<unsigned long long>(s.watchdog_trips));
  out += "\"wake_latency_ns\": " + FiguresJson(s.wake) + ", \"compute_ns\": " + FiguresJson(s.compute) + ", ";
  out += Printf("\"rate_hz\": %.17g, \"fast\": %s, \"realtime_requested\": %s, \"realtime\": %s, ", s.rate_hz,
                s.fast ? "true" : "false", s.realtime_requested ? "true" : "false", s.realtime ? "true" : "false");
  out += "\"rt_refused\": " + JsonString(s.rt_refused) + ", \"end\": " + JsonString(s.end) +
         ", \"fault\": " + JsonString(s.fault) + "}\n";
  return out;
}

}  // namespace palpa::servo
