// The wake-up latency histogram file (shared/record, issue 21): the one writer (palpad
// --latency-histogram), the one parser (palpa bench latency, for palpad's and cyclictest's
// files) and the one percentile definition. Truths are counted by hand.
#include "palpa/record/latency_histogram.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

namespace palpa::record {
namespace {

TEST(LatencyHistogram, SamplePercentileIsTheSameNearestRank) {
  const std::vector<std::int64_t> ns = {50, 10, 40, 20, 30, 100, 90, 80, 70, 60};
  EXPECT_EQ(PercentileOfSamples(ns, 0.5), 50);
  EXPECT_EQ(PercentileOfSamples(ns, 0.99), 100);
  EXPECT_EQ(PercentileOfSamples(ns, 0.9), 90);
  EXPECT_EQ(PercentileOfSamples(ns, 0.0), 10);
  EXPECT_EQ(PercentileOfSamples({}, 0.5), 0);
  // The samples binned at 10 ns give the same ranks (lower edges = the values here).
  std::vector<std::uint32_t> bins(11, 0);
  for (const std::int64_t v : ns) ++bins[static_cast<std::size_t>(v / 10)];
  for (const double q : {0.0, 0.1, 0.35, 0.5, 0.9, 0.99, 1.0})
    EXPECT_EQ(PercentileOfBins<std::uint32_t>(bins, 0, 10, q, 0), PercentileOfSamples(ns, q)) << q;
}

std::string TempFile(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "/palpa_hist_" + std::to_string(::getpid()) + "_" + name;
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

TEST(PercentileOfBins, NearestRankLowerEdgeAndTheMaximumForTheOverflow) {
  const std::vector<std::uint32_t> bins = {0, 2, 1, 0, 1};  // with 1 overflow: n = 5
  const auto p = [&](double q) { return PercentileOfBins<std::uint32_t>(bins, 1, 1000, q, 99'999); };
  EXPECT_EQ(p(0.0), 1000);    // rank 1 (a rank is at least 1)
  EXPECT_EQ(p(0.4), 1000);    // rank 2
  EXPECT_EQ(p(0.5), 2000);    // rank ceil(2.5) = 3
  EXPECT_EQ(p(0.8), 4000);    // rank 4
  EXPECT_EQ(p(1.0), 99'999);  // rank 5 is the overflow: the value the caller passes (the max)
  EXPECT_EQ(p(7.0), 99'999);  // q clamped to 1
  EXPECT_EQ(PercentileOfBins<std::uint32_t>(std::vector<std::uint32_t>(3, 0), 0, 1000, 0.5, 5), 0);  // empty
}

// palpad's file, byte for byte as palpad wrote it before the writer moved to shared/record.
constexpr const char* kPalpadFile =
    "# palpad wake-up latency histogram, 1 us bins (cyclictest -h layout)\n"
    "000000 000000\n"
    "000001 000003\n"
    "000002 000000\n"
    "000003 000001\n"
    "# Total: 000000005\n"
    "# Min Latencies: 00001\n"
    "# Avg Latencies: 00005\n"
    "# Max Latencies: 25000\n"
    "# Histogram Overflows: 00001\n"
    "# palpad max_ns: 25000123\n"
    "# palpad overruns: 2\n"
    "# palpad rt_refused: \n";

TEST(LatencyHistogramFile, PalpadsFileIsCyclictestsLayoutPlusItsOwnLines) {
  const std::vector<std::uint32_t> bins = {0, 3, 0, 1, 0, 0};
  const LatencyTotals totals{5, 1, 1200, 5499.6, 25'000'123};
  const PalpadLine lines[] = {{"overruns", "2"}, {"rt_refused", ""}};
  EXPECT_EQ(FormatLatencyHistogram(bins, totals, lines), kPalpadFile);
}

TEST(LatencyHistogramFile, PalpadsFileReadsBackWithTheExactMaximum) {
  const auto h = ReadLatencyHistogram(TempFile("palpad", kPalpadFile));
  ASSERT_TRUE(h) << h.error();
  EXPECT_EQ(h->bins, (std::vector<std::uint64_t>{0, 3, 0, 1}));
  EXPECT_EQ(h->overflow, 1u);
  EXPECT_EQ(h->count, 5u);
  EXPECT_EQ(h->max_ns, 25'000'123);
  EXPECT_EQ(h->MinNs(), 1000);
  EXPECT_EQ(h->PercentileNs(0.5), 1000);
  EXPECT_EQ(h->PercentileNs(0.8), 3000);
  EXPECT_EQ(h->PercentileNs(1.0), 25'000'123);
  EXPECT_EQ(h->Palpad("overruns"), "2");
  EXPECT_EQ(h->Palpad("rt_refused"), "");
  EXPECT_EQ(h->Palpad("compute_ns"), "?");
}

TEST(LatencyHistogramFile, CyclictestsFileReadsWithTheSameParserAndMerges) {
  const std::string cyclictest =
      "# Histogram\n"
      "000000 000000\n"
      "000001 000005\n"
      "000002 000003\n"
      "# Total: 000000008\n"
      "# Min Latencies: 00001\n"
      "# Avg Latencies: 00001\n"
      "# Max Latencies: 00002\n"
      "# Histogram Overflows: 00000\n"
      "# Histogram Overflow at cycle number:\n"
      "# Thread 0:\n";
  auto h = ReadLatencyHistogram(TempFile("cyclictest", cyclictest));
  ASSERT_TRUE(h) << h.error();
  EXPECT_EQ(h->count, 8u);
  EXPECT_EQ(h->max_ns, 2000);  // µs · 1000: cyclictest has no exact maximum
  EXPECT_TRUE(h->palpad.empty());
  EXPECT_EQ(h->PercentileNs(0.5), 1000);
  EXPECT_EQ(h->PercentileNs(0.7), 2000);
  const auto palpad = ReadLatencyHistogram(TempFile("palpad2", kPalpadFile));
  ASSERT_TRUE(palpad);
  h->Merge(*palpad);
  EXPECT_EQ(h->bins, (std::vector<std::uint64_t>{0, 8, 3, 1}));
  EXPECT_EQ(h->overflow, 1u);
  EXPECT_EQ(h->count, 13u);
  EXPECT_EQ(h->max_ns, 25'000'123);
}

TEST(LatencyHistogramFile, WhatIsNotAHistogramIsRefusedNamingTheFile) {
  const std::string bad = TempFile("bad", "# Max Latencies: 00002\n000001 000005\nnot a bin\n");
  const auto b = ReadLatencyHistogram(bad);
  ASSERT_FALSE(b);
  EXPECT_EQ(b.error(), bad + ":3: not a histogram line: 'not a bin'");
  const std::string no_max = TempFile("nomax", "000001 000005\n");
  const auto n = ReadLatencyHistogram(no_max);
  ASSERT_FALSE(n);
  EXPECT_EQ(n.error(), no_max + ": no '# Max Latencies' line (not a cyclictest histogram)");
  const auto missing = ReadLatencyHistogram(::testing::TempDir() + "/palpa_hist_missing");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().find("palpa_hist_missing: cannot read"), std::string::npos) << missing.error();
}

}  // namespace
}  // namespace palpa::record
