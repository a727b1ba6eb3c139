// The run record (shared/record, issue 21): the one CSV writer and parser palpad, palpa hil and
// palpa view share. Its own test binary, linked against palpa_record alone: the module stands on
// its own (with shared/io).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "palpa/record/run_record.h"

namespace palpa::record {
namespace {

std::string Written(const LogRow& row) {
  char* buffer = nullptr;
  std::size_t size = 0;
  std::FILE* f = open_memstream(&buffer, &size);
  EXPECT_TRUE(WriteCsvHeader(f));
  EXPECT_TRUE(WriteCsvRow(f, row));
  std::fclose(f);
  std::string out(buffer, size);
  std::free(buffer);
  return out;
}

TEST(RunRecord, WrittenRowsParseBackToTheirPrintedDigits) {
  LogRow row;
  row.t_s = 1.25;
  row.hip_m = {0.0123456789012345, -0.002, 1e-7};
  row.proxy_m = {0.0123, -0.00199999, 0};
  row.force_n = {-1.5, 0.123456789123, 8};
  row.contact = true;
  const std::string text = Written(row);
  ASSERT_EQ(text.substr(0, text.find('\n')), kCsvHeader);
  const std::string line = text.substr(text.find('\n') + 1, text.size() - text.find('\n') - 2);
  EXPECT_EQ(line, "1.25,0.0123456789012,-0.002,1e-07,0.0123,-0.00199999,0,-1.5,0.123456789,8,1");
  const auto back = ParseCsvRow(line);
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->t_s, 1.25);
  EXPECT_EQ(back->hip_m[0], 0.0123456789012);  // %.12g
  EXPECT_EQ(back->force_n[1], 0.123456789);    // %.9g
  EXPECT_EQ(back->force_n[2], 8.0);
  EXPECT_TRUE(back->contact);
  EXPECT_EQ(Written(*back).substr(text.find('\n') + 1), line + "\n");  // the digits survive a round trip
}

TEST(RunRecord, BadRowsNameTheField) {
  EXPECT_EQ(ParseCsvRow("0,0,0,0,0,0,0,0,0,0").error(), "expected 11 comma-separated fields");
  EXPECT_EQ(ParseCsvRow("0,0,0,0,0,0,0,0,0,0,0,0").error(), "expected 11 comma-separated fields");
  EXPECT_EQ(ParseCsvRow("0,0,0,0,0,0,abc,0,0,0,0").error(), "field 7 'abc' is not a finite number");
  EXPECT_EQ(ParseCsvRow("0,nan,0,0,0,0,0,0,0,0,0").error(), "field 2 'nan' is not a finite number");
  EXPECT_EQ(ParseCsvRow("0,0,0,0,0,0,0,0,0,0,2").error(), "contact must be 0 or 1, got 2");
  EXPECT_TRUE(ParseCsvRow("0,0,0,0,0,0,0,0,0,0,0"));
}

TEST(RunRecord, TimingRowsAreWrittenAsPalpadAlwaysHasAndParseBack) {
  char* buffer = nullptr;
  std::size_t size = 0;
  std::FILE* f = open_memstream(&buffer, &size);
  ASSERT_TRUE(WriteTimingHeader(f));
  // A paced tick (total = wake + compute) and a fast one (no deadline: total = compute).
  const TimingRow paced{41, 0.041, 12345, 6789, TotalNs(12345, 6789), kFlagClamped | kFlagOverrun};
  const TimingRow fast{0, 0, -1, 5000, TotalNs(-1, 5000), 0};
  ASSERT_TRUE(WriteTimingRow(f, paced));
  ASSERT_TRUE(WriteTimingRow(f, fast));
  std::fclose(f);
  const std::string text(buffer, size);
  std::free(buffer);
  // The bytes palpad wrote before the format had a home (its fprintf, by hand).
  EXPECT_EQ(text,
            "tick,t_s,wake_ns,compute_ns,total_ns,flags\n"
            "41,0.041000000,12345,6789,19134,9\n"
            "0,0.000000000,-1,5000,5000,0\n");
  const auto back = ParseTimingRow("41,0.041000000,12345,6789,19134,9");
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->tick, 41u);
  EXPECT_EQ(back->t_s, 0.041);
  EXPECT_EQ(back->wake_ns, 12345);
  EXPECT_EQ(back->compute_ns, 6789);
  EXPECT_EQ(back->total_ns, 19134);
  EXPECT_EQ(back->flags, kFlagClamped | kFlagOverrun);
  EXPECT_EQ(ParseTimingRow("0,0.000000000,-1,5000,5000,0")->wake_ns, -1);
}

TEST(RunRecord, BadTimingRowsNameTheField) {
  EXPECT_EQ(ParseTimingRow("1,0,2,3,4").error(), "expected 6 comma-separated fields");
  EXPECT_EQ(ParseTimingRow("1,0,2,3,4,5,6").error(), "expected 6 comma-separated fields");
  EXPECT_EQ(ParseTimingRow("1,0,2,3.5,4,5").error(), "field 4 '3.5' is not an integer");
  EXPECT_EQ(ParseTimingRow("-1,0,2,3,4,5").error(), "field 1 '-1' is not an integer");
  EXPECT_EQ(ParseTimingRow("1,inf,2,3,4,5").error(), "field 2 'inf' is not a finite number");
  EXPECT_EQ(ParseTimingRow(std::string(kTimingCsvHeader)).error(), "field 1 'tick' is not an integer");
}

TEST(RunRecord, DeterministicFlagsAreAllButOverrun) {
  EXPECT_EQ(kDeterministicFlags & kFlagOverrun, 0u);
  EXPECT_EQ(kDeterministicFlags | kFlagOverrun, 0x7Fu);  // the seven flags, bits 0-6
}

}  // namespace
}  // namespace palpa::record
