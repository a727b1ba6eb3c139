// palpad's per-tick timing record (--record-timing: tick,t_s,wake_ns,compute_ns,total_ns,flags)
// and the latency figures made of it. Wall-clock figures are reported, never judged (docs/hil.md
// § Real-time mode); the flags column carries the telemetry flags the invariants and goldens use.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "palpa/record/run_record.h"

namespace palpa::hil {

/// One timing row (the run record's: record::TimingRow).
using TimingRow = record::TimingRow;

/// The rows of a timing CSV after its header (record::ParseTimingRow); lines that do not parse
/// are skipped, a missing file is no rows (a case's `output` has none).
[[nodiscard]] std::vector<TimingRow> ReadTiming(const std::filesystem::path& p);

/// Nearest-rank percentiles of a set of durations, µs.
struct Percentiles {
  std::size_t count = 0;  ///< samples ≥ 0 (negative ones, "no deadline", are left out)
  double p50 = 0, p99 = 0, p999 = 0, max = 0;
};
[[nodiscard]] Percentiles Figures(std::vector<std::int64_t> ns);

/// A run's durations by kind, ns, one per timing row (for Figures, per case and over all cases).
struct Latency {
  std::vector<std::int64_t> wake_ns, compute_ns, total_ns;

  static Latency Of(const std::vector<TimingRow>& rows);
  void Append(const Latency& other);
};

}  // namespace palpa::hil
