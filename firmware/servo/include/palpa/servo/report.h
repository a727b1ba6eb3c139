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

/// Output CSV column line (v1). Columns: tick time s, HIP m, proxy m, force N, contact 0/1.
inline constexpr std::string_view kCsvHeader =
    "t_s,hip_x_m,hip_y_m,hip_z_m,proxy_x_m,proxy_y_m,proxy_z_m,fx_n,fy_n,fz_n,contact";

/// Writes the header and `rows` to `out`: times and metres with %.12g, newtons with %.9g (both
/// more digits than a Q16.16 LSB needs), contact 0/1. Same rows → same bytes. False on an I/O error.
bool WriteCsv(std::FILE* out, std::span<const LogRow> rows);

/// A file written under a temporary name in the target's directory and renamed over the target
/// only by Commit(), after fsync: readers see the old file or the complete new one, never a part.
/// Destroying an uncommitted AtomicFile removes the temporary file.
class AtomicFile {
 public:
  /// Creates `<path>.tmp.XXXXXX` (mode 0666 minus umask). Error: a sentence naming the path.
  static std::expected<AtomicFile, std::string> Create(const std::string& path);

  AtomicFile(AtomicFile&& other) noexcept;
  AtomicFile& operator=(AtomicFile&&) = delete;
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  ~AtomicFile();

  std::FILE* file() const { return file_; }
  /// Flushes, fsyncs, closes and renames onto the target, then fsyncs the directory. Errors name
  /// the path; on error the temporary is removed and the target left as it was.
  std::expected<void, std::string> Commit();

 private:
  AtomicFile(std::string path, std::string temp_path, std::FILE* file)
      : path_(std::move(path)), temp_path_(std::move(temp_path)), file_(file) {}

  std::string path_;
  std::string temp_path_;
  std::FILE* file_ = nullptr;
};

/// WriteCsv through an AtomicFile.
std::expected<void, std::string> WriteCsvAtomic(const std::string& path, std::span<const LogRow> rows);

/// The run in numbers, for people (SummaryText) and scripts (SummaryJson).
struct ServoSummary {
  std::uint64_t ticks = 0;
  std::uint64_t contact_ticks = 0;
  double max_force_n = 0;
  double max_penetration_mm = 0;
  std::int64_t median_tick_ns = 0;  ///< over logged ticks (upper median); 0 if none
  std::int64_t p99_tick_ns = 0;     ///< nearest-rank 99th percentile over logged ticks; 0 if none
  std::uint64_t force_clamps = 0;
  std::uint64_t device_errors = 0;
  std::uint64_t overruns = 0;
  std::uint64_t dropped_rows = 0;
  double rate_hz = 0;
  bool fast = false;
};

/// Nearest-rank percentile (q in [0, 1]) of `ns` by nth_element on a copy; 0 for an empty span.
std::int64_t PercentileNs(std::span<const std::int64_t> ns, double q);

ServoSummary Summarize(const ServoLoop& loop, bool fast, double rate_hz);

/// `key: value` lines: ticks, ticks in contact, max force (N), max penetration (mm),
/// median tick (ns), p99 tick (ns), force clamps, device errors, overruns, dropped rows,
/// mode (fast | paced at N Hz).
std::string SummaryText(const ServoSummary& s);

/// One JSON object: ticks, contact_ticks, max_force_n, max_penetration_mm, median_tick_ns,
/// p99_tick_ns, force_clamps, device_errors, overruns, dropped_rows, rate_hz, fast.
std::string SummaryJson(const ServoSummary& s);

}  // namespace palpa::servo
