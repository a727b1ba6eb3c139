#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>

#include "palpa/blob/blob.h"
#include "palpa/trace/trace.h"

namespace palpa::trace {
namespace {

std::span<const std::byte> Bytes(const std::string& s) { return std::as_bytes(std::span(s.data(), s.size())); }

// ---- v1 (the shim) ----

TEST(TraceV1, ParsesCommentsHeaderAndSamples) {
  auto t = ParseTrace("# made by hand\nt_s,x_m,y_m,z_m\n0,0,0,0\n\n0.5, 0.01 ,0,-0.02\n1,0.02,0,0\n", "hand.csv");
  ASSERT_TRUE(t.has_value()) << t.error().message;
  ASSERT_EQ(t->size(), 3u);
  EXPECT_DOUBLE_EQ((*t)[1].hip_m[2], -0.02);
  EXPECT_EQ((*t)[1].buttons, 0);
}

TEST(TraceV1, OldWriterOutputStillReads) {
  // Exactly what the v1 writer (palpa trace synth before issue 10) produced.
  const std::string v1 =
      "# palpa trace v1: HIP in device-frame metres, time in seconds\n"
      "# palpa trace synth --kind stroke ...\n"
      "t_s,x_m,y_m,z_m\n"
      "0,0.0006776953763,0.01770776056,0.02198207824\n"
      "0.001,0.0006776953763,0.01770776056,0.02198207824\n";
  auto f = ParseTraceBytes(Bytes(v1), "old.csv");
  ASSERT_TRUE(f.has_value()) << f.error().message;
  EXPECT_EQ(f->info.version, 1);
  EXPECT_FALSE(f->info.binary);
  ASSERT_EQ(f->samples.size(), 2u);
  EXPECT_EQ(f->samples[1].hip_m[0], 0.0006776953763);  // v1 keeps every digit it was given
  EXPECT_EQ(f->samples[1].t_s, 0.001);
}

TEST(TraceV1, ErrorsNameFileAndLine) {
  auto t = ParseTrace("0,0,0,0\n0.1,0,0\n", "bad.csv");
  ASSERT_FALSE(t.has_value());
  EXPECT_EQ(t.error().line, 2u);
  EXPECT_NE(t.error().message.find("bad.csv:2:"), std::string::npos) << t.error().message;

  t = ParseTrace("0,0,0,0\n0.1,0,nan,0\n", "nan.csv");
  ASSERT_FALSE(t.has_value());
  EXPECT_EQ(t.error().line, 2u);

  t = ParseTrace("0,0,0,0\n0.2,0,0,0\n0.1,0,0,0\n", "time.csv");
  ASSERT_FALSE(t.has_value());
  EXPECT_EQ(t.error().line, 3u);
  EXPECT_NE(t.error().message.find("does not increase"), std::string::npos) << t.error().message;

  t = ParseTrace("0,0,0,0\n0.1,0,0,0.5\n", "far.csv");  // half a metre above the Falcon
  ASSERT_FALSE(t.has_value());
  EXPECT_EQ(t.error().line, 2u);
  EXPECT_NE(t.error().message.find("far.csv:2: HIP (0, 0, 0.5) m is outside the Falcon workspace"), std::string::npos)
      << t.error().message;

  t = ParseTrace("0,0,0,0\n", "short.csv");
  ASSERT_FALSE(t.has_value());

  EXPECT_FALSE(ReadTrace("/nonexistent/trace.csv").has_value());
}

// ---- v2 text ----

constexpr const char* kHeader4 = "# palpa-trace v2 units=s,m frame=device columns=t_s,x_m,y_m,z_m\n";
constexpr const char* kHeader5 = "# palpa-trace v2 units=s,m frame=device columns=t_s,x_m,y_m,z_m,buttons\n";

TEST(TraceV2, ParsesHeaderCommentsAndButtons) {
  const std::string text =
      std::string(kHeader5) + "# made by hand\n# second line\n0,0.001,0.002,0.003,0\n0.001,0.001,0.002,0.0029,5\n";
  auto f = ParseTraceBytes(Bytes(text), "b.csv");
  ASSERT_TRUE(f.has_value()) << f.error().message;
  EXPECT_EQ(f->info.version, 2);
  EXPECT_TRUE(f->info.has_buttons);
  EXPECT_EQ(f->info.comment, "made by hand\nsecond line");
  ASSERT_EQ(f->samples.size(), 2u);
  EXPECT_EQ(f->samples[1].buttons, 5);
  EXPECT_EQ(f->samples[1].hip_m[2], 0.0029);
}

TEST(TraceV2, HeaderIsChecked) {
  const struct {
    std::string text;
    const char* expect;
  } cases[] = {
      {"# palpa-trace v3 units=s,m frame=device columns=t_s,x_m,y_m,z_m\n0,0,0,0\n1,0,0,0\n",
       "h.csv:1: trace format v3 is not supported"},
      {"# palpa-trace v2 units=ms,mm frame=device columns=t_s,x_m,y_m,z_m\n0,0,0,0\n1,0,0,0\n",
       "h.csv:1: units must be s,m"},
      {"# palpa-trace v2 units=s,m columns=t_s,x_m,y_m,z_m\n0,0,0,0\n1,0,0,0\n", "h.csv:1: header line lacks frame"},
      {"# palpa-trace v2 units=s,m frame=device columns=t,x,y,z\n0,0,0,0\n1,0,0,0\n", "h.csv:1: columns must be"},
      {"# palpa-trace v2 units=s,m frame=device columns=t_s,x_m,y_m,z_m colour=red\n0,0,0,0\n1,0,0,0\n",
       "h.csv:1: unknown header key 'colour'"},
      // Row shape follows the header's columns.
      {std::string(kHeader4) + "0,0,0,0\n1,0,0,0,1\n", "h.csv:3: more than 4 values"},
      {std::string(kHeader5) + "0,0,0,0,0\n1,0,0,0\n", "h.csv:3: expected 5 values"},
      {std::string(kHeader5) + "0,0,0,0,0\n1,0,0,0,256\n", "h.csv:3: buttons must be an integer 0..255"},
      {std::string(kHeader5) + "0,0,0,0,0\n1,0,0,0,1.5\n", "h.csv:3: expected ','"},
      {std::string(kHeader4) + "0,0,0,0\n0,0,0,0\n", "h.csv:3: time 0 s does not increase"},
      {std::string(kHeader4) + "0,0,0,0\n1,inf,0,0\n", "h.csv:3: position x is not finite"},
      {std::string(kHeader4) + "0,0,0,0\n1,0,-0.0601,0\n", "h.csv:3: HIP (0, -0.0601, 0) m is outside"},
  };
  for (const auto& c : cases) {
    auto f = ParseTraceBytes(Bytes(c.text), "h.csv");
    ASSERT_FALSE(f.has_value()) << c.text;
    EXPECT_NE(f.error().message.find(c.expect), std::string::npos) << f.error().message << "\nexpected: " << c.expect;
  }
}

TEST(TraceV2, WriterPrintsNanometresAndNanoseconds) {
  // Hand-computed: 0.0123456789 m rounds to 12345679 nm; −0.0000000004 m to −0 nm → "0.000000000";
  // 1.0000000006 s to 1000000001 ns.
  const std::vector<TraceSample> s = {{0.0, {0.0123456789, -0.0000000004, -0.05}, 0},
                                      {1.0000000006, {-0.0123456781, 0.06, 0.0}, 0}};
  const std::string text = FormatTrace(s, "line one\nline two");
  EXPECT_EQ(text,
            "# palpa-trace v2 units=s,m frame=device columns=t_s,x_m,y_m,z_m\n"
            "# line one\n# line two\n"
            "0.000000000,0.012345679,0.000000000,-0.050000000\n"
            "1.000000001,-0.012345678,0.060000000,0.000000000\n");
  auto back = ParseTrace(text, "w.csv");
  ASSERT_TRUE(back.has_value()) << back.error().message;
  EXPECT_EQ((*back)[0].hip_m[0], 0.012345679);
  EXPECT_EQ((*back)[1].t_s, 1.000000001);
}

TEST(TraceV2, ButtonsColumnAppearsWhenAnySampleHasButtons) {
  const std::vector<TraceSample> s = {{0.0, {0, 0, 0}, 0}, {0.001, {0, 0, 0}, 9}};
  const std::string text = FormatTrace(s, "");
  EXPECT_NE(text.find("columns=t_s,x_m,y_m,z_m,buttons\n"), std::string::npos);
  EXPECT_NE(text.find("0.001000000,0.000000000,0.000000000,0.000000000,9\n"), std::string::npos);
}

// ---- binary ----

std::vector<TraceSample> Wiggle(std::size_t n, bool buttons) {
  std::vector<TraceSample> s;
  for (std::size_t i = 0; i < n; ++i) {
    const double t = 0.25 + static_cast<double>(i) * 1e-3;
    s.push_back(
        {t,
         {0.01 * std::sin(7.0 * t), -0.02 + 0.003 * std::cos(3.0 * t), 0.0001234567891 * static_cast<double>(i % 7)},
         static_cast<std::uint8_t>(buttons ? i % 16 : 0)});
  }
  return s;
}

TEST(TraceBinary, HandComputedLayout) {
  const std::vector<TraceSample> s = {{0.5, {0.001, -0.002, 0.0}, 0}, {0.501, {0.001, -0.002, 0.000000003}, 0}};
  auto bin = EncodeBinaryTrace(s, "hi");
  ASSERT_TRUE(bin.has_value()) << bin.error().message;
  ASSERT_EQ(bin->size(), 64u + 2u + 2u * 16u);
  const auto* b = reinterpret_cast<const unsigned char*>(bin->data());
  EXPECT_EQ(std::memcmp(b, "PALPATRC", 8), 0);
  EXPECT_EQ(b[8], 2);    // version
  EXPECT_EQ(b[10], 0);   // flags
  EXPECT_EQ(b[12], 64);  // header size
  EXPECT_EQ(b[14], 16);  // record size
  EXPECT_EQ(b[16], 2);   // sample count
  std::int64_t t0 = 0;
  std::memcpy(&t0, b + 24, 8);
  EXPECT_EQ(t0, 500000000);  // 0.5 s in ns
  EXPECT_EQ(b[32], 2);       // comment bytes
  EXPECT_EQ(b[40], 2 + 32);  // payload
  EXPECT_EQ(std::memcmp(b + 64, "hi", 2), 0);
  // Record 0: dt 0, x = 1,000,000 nm = 0x000F4240, y = −2,000,000 nm = 0xFFE17B80, z = 0.
  const unsigned char r0[16] = {0, 0, 0, 0, 0x40, 0x42, 0x0F, 0, 0x80, 0x7B, 0xE1, 0xFF, 0, 0, 0, 0};
  EXPECT_EQ(std::memcmp(b + 66, r0, 16), 0);
  // Record 1: dt 1,000,000 ns = 0x000F4240, z = 3 nm.
  const unsigned char r1[16] = {0x40, 0x42, 0x0F, 0, 0x40, 0x42, 0x0F, 0, 0x80, 0x7B, 0xE1, 0xFF, 3, 0, 0, 0};
  EXPECT_EQ(std::memcmp(b + 82, r1, 16), 0);
  // CRC-32C over [0, 60) then the payload, as blob::Crc32c computes it (its own check value is tested).
  std::uint32_t crc = blob::Crc32c(std::as_bytes(std::span(bin->data(), 60)));
  crc = blob::Crc32c(std::as_bytes(std::span(bin->data() + 64, bin->size() - 64)), crc);
  std::uint32_t stored = 0;
  std::memcpy(&stored, b + 60, 4);
  EXPECT_EQ(stored, crc);
}

TEST(TraceBinary, ReadsBackTheSameDoublesAsTheTextForm) {
  for (const bool buttons : {false, true}) {
    const auto s = Wiggle(500, buttons);
    auto bin = EncodeBinaryTrace(s, "wiggle");
    ASSERT_TRUE(bin.has_value()) << bin.error().message;
    auto from_bin = ParseTraceBytes(Bytes(*bin), "w.ptb");
    ASSERT_TRUE(from_bin.has_value()) << from_bin.error().message;
    EXPECT_TRUE(from_bin->info.binary);
    EXPECT_EQ(from_bin->info.has_buttons, buttons);
    EXPECT_EQ(from_bin->info.comment, "wiggle");
    const std::string text = FormatTrace(s, "wiggle");
    auto from_text = ParseTraceBytes(Bytes(text), "w.csv");
    ASSERT_TRUE(from_text.has_value()) << from_text.error().message;
    ASSERT_EQ(from_bin->samples.size(), s.size());
    ASSERT_EQ(from_text->samples.size(), s.size());
    for (std::size_t i = 0; i < s.size(); ++i) {
      EXPECT_EQ(from_bin->samples[i].t_s, from_text->samples[i].t_s) << i;
      EXPECT_EQ(from_bin->samples[i].hip_m, from_text->samples[i].hip_m) << i;
      EXPECT_EQ(from_bin->samples[i].buttons, from_text->samples[i].buttons) << i;
      for (std::size_t k = 0; k < 3; ++k) EXPECT_NEAR(from_bin->samples[i].hip_m[k], s[i].hip_m[k], 0.5e-9);
    }
    // Text written from what was read is the same text: the encodings are lossless between them.
    EXPECT_EQ(FormatTrace(from_bin->samples, from_bin->info.comment), text);
    // And the binary form is smaller than the text.
    EXPECT_LT(bin->size() * 2, text.size());
  }
}

TEST(TraceBinary, CorruptionIsRefusedWithTheByte) {
  auto bin = EncodeBinaryTrace(Wiggle(10, false), "");
  ASSERT_TRUE(bin.has_value());
  {
    std::string bad = *bin;
    bad[64 + 16 * 3 + 5] ^= 0x01;  // one bit of a position
    auto f = ParseTraceBytes(Bytes(bad), "c.ptb");
    ASSERT_FALSE(f.has_value());
    EXPECT_NE(f.error().message.find("c.ptb: byte 60: checksum mismatch"), std::string::npos) << f.error().message;
  }
  {
    std::string bad = *bin;
    bad[8] = 3;
    auto f = ParseTraceBytes(Bytes(bad), "c.ptb");
    ASSERT_FALSE(f.has_value());
    EXPECT_EQ(f.error().byte, 8u);
    EXPECT_NE(f.error().message.find("version 3 is not supported"), std::string::npos) << f.error().message;
  }
  {
    const std::string bad = bin->substr(0, bin->size() - 1);
    auto f = ParseTraceBytes(Bytes(bad), "c.ptb");
    ASSERT_FALSE(f.has_value());
    EXPECT_EQ(f.error().byte, 40u) << f.error().message;
  }
  {
    auto f = ParseTraceBytes(Bytes(bin->substr(0, 30)), "c.ptb");
    ASSERT_FALSE(f.has_value());
    EXPECT_NE(f.error().message.find("shorter than its 64-byte header"), std::string::npos);
  }
}

// A record the checksum accepts but the sample checks refuse: the error names the record's byte.
std::string WithRecordField(std::string bin, std::size_t record, std::size_t field_offset, std::int32_t value) {
  std::memcpy(bin.data() + 64 + 16 * record + field_offset, &value, 4);
  const auto bytes = std::as_bytes(std::span(bin.data(), bin.size()));
  std::uint32_t crc = blob::Crc32c(bytes.first(60));
  crc = blob::Crc32c(bytes.subspan(64), crc);
  std::memcpy(bin.data() + 60, &crc, 4);
  return bin;
}

TEST(TraceBinary, SampleChecksNameTheRecordByte) {
  auto bin = EncodeBinaryTrace(Wiggle(10, false), "");
  ASSERT_TRUE(bin.has_value());
  auto f = ParseTraceBytes(Bytes(WithRecordField(*bin, 4, 8, 70'000'000)), "w.ptb");  // y = 0.07 m
  ASSERT_FALSE(f.has_value());
  EXPECT_EQ(f.error().byte, 64u + 16u * 4u + 4u);
  EXPECT_NE(f.error().message.find("sample 4: HIP"), std::string::npos) << f.error().message;
  f = ParseTraceBytes(Bytes(WithRecordField(*bin, 6, 0, 0)), "w.ptb");  // dt 0
  ASSERT_FALSE(f.has_value());
  EXPECT_EQ(f.error().byte, 64u + 16u * 6u);
  EXPECT_NE(f.error().message.find("time does not increase"), std::string::npos) << f.error().message;
}

TEST(TraceBinary, WriterRefusesWhatItCannotStore) {
  std::vector<TraceSample> s = {{0.0, {0, 0, 0}, 0}, {5.0, {0, 0, 0}, 0}};
  auto bin = EncodeBinaryTrace(s, "");
  ASSERT_FALSE(bin.has_value());
  EXPECT_NE(bin.error().message.find("gap over 4.29 s"), std::string::npos);
  s[1].t_s = 0.2e-9;  // strictly later, but the same nanosecond
  bin = EncodeBinaryTrace(s, "");
  ASSERT_FALSE(bin.has_value());
  EXPECT_NE(bin.error().message.find("less than 1 ns"), std::string::npos);
  s[1] = {1.0, {0, 0.2, 0}, 0};
  bin = EncodeBinaryTrace(s, "");
  ASSERT_FALSE(bin.has_value());
  EXPECT_NE(bin.error().message.find("sample 1: HIP"), std::string::npos);
}

// ---- streaming (palpad --record) ----

std::string ReadAll(std::FILE* f) {
  std::string out;
  std::rewind(f);
  char buf[4096];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) out.append(buf, n);
  return out;
}

TEST(TraceStream, BinaryStreamEqualsTheOneShotEncoderAndRefusesBadSamples) {
  const auto s = Wiggle(300, true);
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  TraceStreamWriter w(f, true, "recorded");
  ASSERT_TRUE(w.Begin());
  for (std::size_t i = 0; i < s.size(); ++i) {
    EXPECT_TRUE(w.Add(s[i]));
    if (i == 100) {
      EXPECT_FALSE(w.Add(s[i]));                               // same time again
      EXPECT_FALSE(w.Add({s[i].t_s + 1e-4, {0, 0, 0.2}, 0}));  // outside the workspace
    }
  }
  ASSERT_TRUE(w.Finish().has_value());
  EXPECT_EQ(w.written(), 300u);
  EXPECT_EQ(w.refused(), 2u);
  auto one_shot = EncodeBinaryTrace(s, "recorded", true);
  ASSERT_TRUE(one_shot.has_value());
  EXPECT_TRUE(ReadAll(f) == *one_shot);
  std::fclose(f);
}

TEST(TraceStream, TextStreamEqualsFormatTrace) {
  const auto s = Wiggle(50, false);
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  TraceStreamWriter w(f, false, "recorded");
  ASSERT_TRUE(w.Begin());
  for (const auto& x : s) EXPECT_TRUE(w.Add(x));
  ASSERT_TRUE(w.Finish().has_value());
  EXPECT_EQ(ReadAll(f), FormatTrace(s, "recorded", true));
  std::fclose(f);
  // One sample is not a trace.
  f = std::tmpfile();
  TraceStreamWriter one(f, true, "");
  ASSERT_TRUE(one.Begin());
  EXPECT_TRUE(one.Add(s[0]));
  EXPECT_FALSE(one.Finish().has_value());
  std::fclose(f);
}

// ---- workspace ----

TEST(TraceWorkspace, HoldsTheDocumentedFalconRange) {
  // docs/falcon.md §4: grip z 0.075..0.175 m in the Falcon frame, device frame = Falcon − (0, 0, 0.125).
  EXPECT_TRUE(kFalconWorkspace.Contains({0, 0, 0.075 - 0.125}));
  EXPECT_TRUE(kFalconWorkspace.Contains({0, 0, 0.175 - 0.125}));
  // The virtual Falcon's hand: pulled out to z 0.174, homing in to 0.100 (docs/falcon.md §6).
  EXPECT_TRUE(kFalconWorkspace.Contains({0, 0, 0.174 - 0.125}));
  EXPECT_TRUE(kFalconWorkspace.Contains({0.06, -0.06, 0.0}));
  EXPECT_FALSE(kFalconWorkspace.Contains({0.0601, 0, 0}));
  EXPECT_FALSE(kFalconWorkspace.Contains({0, 0, -0.0601}));
  EXPECT_FALSE(kFalconWorkspace.Contains({std::nan(""), 0, 0}));
}

TEST(Trace, HipAtInterpolatesLinearlyAndClamps) {
  std::vector<TraceSample> s = {{0.0, {0, 0, 0}}, {1.0, {1, 2, 3}}, {3.0, {1, 2, -1}}};
  std::size_t hint = 0;
  auto a = HipAt(s, 0.25, hint);
  EXPECT_DOUBLE_EQ(a[0], 0.25);
  EXPECT_DOUBLE_EQ(a[1], 0.5);
  a = HipAt(s, 2.0, hint);
  EXPECT_DOUBLE_EQ(a[2], 1.0);
  a = HipAt(s, 9.0, hint);
  EXPECT_DOUBLE_EQ(a[2], -1.0);
  a = HipAt(s, -1.0, hint);  // going back resets the cursor
  EXPECT_DOUBLE_EQ(a[0], 0.0);
}

}  // namespace
}  // namespace palpa::trace
