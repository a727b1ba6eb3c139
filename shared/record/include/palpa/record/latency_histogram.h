// The wake-up latency histogram file (issue 9; here since issue 21): palpad writes it after a run
// (--latency-histogram) in cyclictest's histogram file layout (rt-tests `-h US --histfile`), and
// `palpa bench latency` reads palpad's and cyclictest's files with one parser, so both sides of
// the comparison use one percentile definition (PercentileOfBins, also behind the servo loop's
// own histograms, firmware/rt/include/palpa/rt/histogram.h). docs/runtime.md § Latency. Non-RT
// except PercentileOfBins, which allocates nothing.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace palpa::record {

/// Nearest-rank percentile over binned counts: the lower edge (bin index · bin_ns) of the first
/// bin at which the running count reaches ceil(q·n), n = Σbins + overflow. If that rank lies in
/// the overflow, returns `overflow_value_ns` (callers pass the exact maximum: an upper bound).
/// q is clamped to [0, 1]; returns 0 when n = 0. Shared by the servo loop's histograms and the
/// parser of the histogram files, so both sides of a comparison use one definition.
/// The same nearest rank over raw samples: the smallest value with at least ceil(q·n) values ≤ it
/// (q clamped to [0, 1], rank at least 1); 0 when there are none. Non-RT (sorts a copy).
std::int64_t PercentileOfSamples(std::span<const std::int64_t> ns, double q);

template <typename Count>
std::int64_t PercentileOfBins(std::span<const Count> bins, std::uint64_t overflow, std::int64_t bin_ns, double q,
                              std::int64_t overflow_value_ns) {
  std::uint64_t n = overflow;
  for (const Count c : bins) n += c;
  if (n == 0) return 0;
  const double qc = std::clamp(q, 0.0, 1.0);
  auto rank = static_cast<std::uint64_t>(std::ceil(qc * static_cast<double>(n)));
  rank = std::clamp<std::uint64_t>(rank, 1, n);
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < bins.size(); ++i) {
    seen += bins[i];
    if (seen >= rank) return static_cast<std::int64_t>(i) * bin_ns;
  }
  return overflow_value_ns;
}

/// A "# palpad <key>: <value>" line of palpad's file.
using PalpadLine = std::pair<std::string, std::string>;

/// The run's totals that the file's "# ..." lines carry besides the bins.
struct LatencyTotals {
  std::uint64_t count = 0;     ///< values recorded, overflow included
  std::uint64_t overflow = 0;  ///< values beyond the last bin
  std::int64_t min_ns = 0;     ///< exact
  double mean_ns = 0;
  std::int64_t max_ns = 0;  ///< exact
};

/// palpad's file for 1 µs bins `bins` (bin i counts [i, i+1) µs): "%06d %06d" per bin up to the
/// last non-empty one, then "# Total:", "# Min Latencies:", "# Avg Latencies:", "# Max Latencies:"
/// (µs, truncated; the mean rounded), "# Histogram Overflows:", "# palpad max_ns:" (the exact
/// maximum), then `lines` as "# palpad <key>: <value>".
std::string FormatLatencyHistogram(std::span<const std::uint32_t> bins, const LatencyTotals& totals,
                                   std::span<const PalpadLine> lines);

/// One histogram file as read back: palpad's or cyclictest's (one thread).
struct LatencyHistogram {
  std::vector<std::uint64_t> bins;  ///< count per 1 µs bin
  std::uint64_t overflow = 0;       ///< "# Histogram Overflows"
  std::uint64_t count = 0;          ///< Σbins + overflow
  std::int64_t max_ns = 0;          ///< exact for palpad ("# palpad max_ns"), µs·1000 for cyclictest
  std::vector<PalpadLine> palpad;   ///< palpad's own lines, in file order (none for cyclictest)

  /// PercentileOfBins over the 1 µs bins, the maximum for a rank in the overflow: ns, a multiple
  /// of 1000 unless it is the maximum.
  std::int64_t PercentileNs(double q) const { return PercentileOfBins<std::uint64_t>(bins, overflow, 1000, q, max_ns); }
  /// Lower edge of the first non-empty bin, ns; the maximum if every value is in the overflow.
  std::int64_t MinNs() const;
  /// The value of palpad's line `key`, or "?" when the file has none.
  std::string Palpad(std::string_view key) const;
  /// Adds `other`'s counts (bins, overflow, count) and keeps the larger maximum; the palpad lines
  /// stay this file's.
  void Merge(const LatencyHistogram& other);
};

/// Reads a histogram file (regular files only, lines of at most 4 KiB). Error: a sentence naming
/// the file ("<path>:<line>: not a histogram line: '…'", "<path>: no '# Max Latencies' line (not
/// a cyclictest histogram)", or why it cannot be read).
std::expected<LatencyHistogram, std::string> ReadLatencyHistogram(const std::string& path);

}  // namespace palpa::record
