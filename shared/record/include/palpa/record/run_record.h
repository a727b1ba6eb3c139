// The run record (issue 21): what palpad writes for every tick and what the host reads back —
// the output CSV's columns, one writer and one parser, and the telemetry flags. palpad writes
// it (firmware/servo), `palpa hil` parses it against its goldens, `palpa view` plots it.
// docs/runtime.md § Output. Non-RT: the telemetry drain and the host call these, never a tick.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <expected>
#include <string>
#include <string_view>
#include <type_traits>

namespace palpa::record {

/// Output CSV column line (v1). Columns: tick time s, HIP m, proxy m, force N, contact 0/1.
inline constexpr std::string_view kCsvHeader =
    "t_s,hip_x_m,hip_y_m,hip_z_m,proxy_x_m,proxy_y_m,proxy_z_m,fx_n,fy_n,fz_n,contact";
inline constexpr std::size_t kCsvColumns = 11;

/// One tick as the output CSV row. Device frame.
struct LogRow {
  double t_s = 0;                   ///< device time of the HIP sample, s
  std::array<double, 3> hip_m{};    ///< HIP as read, m
  std::array<double, 3> proxy_m{};  ///< proxy after the tick, m (the Q16.16 grid position converted)
  std::array<double, 3> force_n{};  ///< force written, N (the Q16.16 force converted exactly, times the ramp)
  bool contact = false;             ///< proxy held apart from the HIP by the surface
};
static_assert(std::is_trivially_copyable_v<LogRow>);

/// TelemetrySample::flags bits (firmware/servo/servo_loop.h), also in palpad's timing record.
enum TelemetryFlag : std::uint32_t {
  kFlagClamped = 1u << 0,    ///< |f| hit max_force
  kFlagEstop = 1u << 1,      ///< e-stop asserted: zero force, proxy not run
  kFlagRamp = 1u << 2,       ///< force scaled down while ramping in after an e-stop
  kFlagOverrun = 1u << 3,    ///< the tick ended after the next deadline
  kFlagGpioError = 1u << 4,  ///< a GPIO access failed this tick
  kFlagSwap = 1u << 5,       ///< this tick took a new field (OfferField) at its start
  kFlagSwapRamp = 1u << 6,   ///< force scaled down while ramping in after a field swap
};
/// The flags a replay reproduces bit for bit: all but overrun (wall-clock, paced runs only).
inline constexpr std::uint32_t kDeterministicFlags =
    kFlagClamped | kFlagEstop | kFlagRamp | kFlagGpioError | kFlagSwap | kFlagSwapRamp;

/// The header line alone.
bool WriteCsvHeader(std::FILE* out);
/// One row: times and metres with %.12g, newtons with %.9g (both more digits than a Q16.16 LSB
/// needs), contact 0/1. Same row → same bytes. False on an I/O error.
bool WriteCsvRow(std::FILE* out, const LogRow& row);

/// One data row (no line end) back into a LogRow: kCsvColumns comma-separated finite numbers,
/// contact 0 or 1. Error: a sentence naming the field ("field 3 'x' is not a finite number"),
/// for the caller to prefix with the file and line.
std::expected<LogRow, std::string> ParseCsvRow(std::string_view line);

// ---- The timing record (palpad --record-timing): one row per tick, the wall-clock side ----

/// Timing CSV column line. Columns: tick number, device time s, wake latency ns (−1: no deadline,
/// fast mode or the first tick), compute ns (read → force written), total ns, flags
/// (TelemetryFlag bits).
inline constexpr std::string_view kTimingCsvHeader = "tick,t_s,wake_ns,compute_ns,total_ns,flags";
inline constexpr std::size_t kTimingCsvColumns = 6;

/// One tick of the timing record.
struct TimingRow {
  std::uint64_t tick = 0;
  double t_s = 0;               ///< device time of the HIP sample, s
  std::int64_t wake_ns = -1;    ///< deadline to wake-up; −1 where there is no deadline
  std::int64_t compute_ns = 0;  ///< wake-up (or read) to force written
  std::int64_t total_ns = 0;    ///< TotalNs(wake_ns, compute_ns)
  std::uint32_t flags = 0;      ///< TelemetryFlag bits
};
static_assert(std::is_trivially_copyable_v<TimingRow>);

/// A tick's total: deadline to force written when paced (wake + compute), else compute alone.
constexpr std::int64_t TotalNs(std::int64_t wake_ns, std::int64_t compute_ns) {
  return wake_ns >= 0 ? wake_ns + compute_ns : compute_ns;
}

/// The timing header line alone.
bool WriteTimingHeader(std::FILE* out);
/// One timing row: integers exactly, t_s with %.9f. Same row → same bytes. False on an I/O error.
bool WriteTimingRow(std::FILE* out, const TimingRow& row);
/// One timing data row (no line end) back: kTimingCsvColumns comma-separated numbers, the
/// integers exact. Error: a sentence naming the field, for the caller to prefix with the file and
/// line.
std::expected<TimingRow, std::string> ParseTimingRow(std::string_view line);

}  // namespace palpa::record
