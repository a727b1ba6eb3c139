// Fixed-bin latency histograms for the servo loop: wake-up latency and compute time per tick.
// Fixed storage (no allocation after construction), O(1) Add, percentiles by nearest rank.
//
// Bin convention (the one cyclictest's -h histogram uses, so the two compare directly): bin i
// counts values in [i·bin, (i+1)·bin); a percentile is reported as its bin's lower edge, i.e.
// truncated to the bin width. Values ≥ kBins·bin go to an overflow count; min/max are exact.
// Percentiles follow the run record's one definition (record::PercentileOfBins), which palpa bench
// latency applies to the histogram files.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>

#include "palpa/record/latency_histogram.h"

namespace palpa::rt {

/// kBins bins of kBinNs nanoseconds each. Counts are 32-bit and saturate (2^32 ticks is 5 days at
/// 10 kHz); the total, min, max and sum are 64-bit. RT-safe: Add is O(1), no allocation.
template <std::int64_t kBinNs, std::size_t kBins>
class LinearHistogram {
  static_assert(kBinNs > 0 && kBins > 0);

 public:
  static constexpr std::int64_t kBinWidthNs = kBinNs;
  static constexpr std::int64_t kRangeNs = kBinNs * static_cast<std::int64_t>(kBins);

  /// Records one value, ns. Negative values (a clock that stepped back) count in bin 0.
  void Add(std::int64_t ns) noexcept {
    const std::int64_t v = ns < 0 ? 0 : ns;
    if (v < kRangeNs) {
      std::uint32_t& c = bins_[static_cast<std::size_t>(v / kBinNs)];
      if (c != std::numeric_limits<std::uint32_t>::max()) ++c;
    } else {
      ++overflow_;
    }
    ++count_;
    sum_ns_ += v;
    min_ns_ = std::min(min_ns_, v);
    max_ns_ = std::max(max_ns_, v);
  }

  void Reset() noexcept { *this = LinearHistogram(); }

  std::uint64_t count() const { return count_; }
  std::uint64_t overflow() const { return overflow_; }
  /// Exact extremes, ns (0 when empty).
  std::int64_t min_ns() const { return count_ == 0 ? 0 : min_ns_; }
  std::int64_t max_ns() const { return max_ns_; }
  double mean_ns() const { return count_ == 0 ? 0.0 : static_cast<double>(sum_ns_) / static_cast<double>(count_); }
  std::span<const std::uint32_t> bins() const { return bins_; }

  /// Nearest-rank percentile, ns, as record::PercentileOfBins (bin lower edge; the exact max if the
  /// rank is in the overflow). Non-RT by use (O(kBins)), allocation-free.
  std::int64_t PercentileNs(double q) const {
    return record::PercentileOfBins<std::uint32_t>(bins_, overflow_, kBinNs, q, max_ns_);
  }

 private:
  std::array<std::uint32_t, kBins> bins_{};
  std::uint64_t overflow_ = 0;
  std::uint64_t count_ = 0;
  std::int64_t sum_ns_ = 0;
  std::int64_t min_ns_ = std::numeric_limits<std::int64_t>::max();
  std::int64_t max_ns_ = 0;
};

}  // namespace palpa::rt
