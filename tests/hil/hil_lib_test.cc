// The harness library (hil/: palpa_hil) piece by piece, without palpa or palpad: the golden codec
// and its errors, the case list's errors, palpad's output parser, the invariants on hand-made runs
// over an analytic sphere, and the field probe on the committed blob. tests/hil/hil_test.cc runs
// the whole `palpa hil` against the goldens.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <expected>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>
#include <string>
#include <utility>
#include <vector>

#include "palpa/hil/field_probe.h"
#include "palpa/hil/golden.h"
#include "palpa/hil/invariants.h"
#include "palpa/hil/replay.h"
#include "palpa/hil/suite.h"
#include "palpa/hil/timing.h"
#include "palpa/record/run_record.h"

namespace {

namespace fs = std::filesystem;
namespace hil = palpa::hil;

fs::path TempDir(const std::string& name) {
  const fs::path d = fs::path(::testing::TempDir()) / ("palpa-hil-lib-" + name + "-" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// ---------------------------------------------------------------- golden codec

// Forces that exercise the varint (one to five bytes, both signs) and every per-tick byte.
std::vector<hil::Tick> SomeTicks(std::size_t n) {
  std::vector<hil::Tick> ticks(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto s = static_cast<std::int32_t>(i);
    ticks[i].force_q24 = {s * 4099 - 70000, (s % 7 == 0 ? -1 : 1) * ((s % 1000) << 20), s % 3 == 0 ? 0 : -s};
    for (std::size_t k = 0; k < 3; ++k) ticks[i].force[k] = ticks[i].force_q24[k] / hil::kForceScale;
    ticks[i].contact = i % 5 != 0;
    ticks[i].flags = static_cast<std::uint8_t>(i % 64);
    ticks[i].row_hash = static_cast<std::uint16_t>(i * 40503u);
  }
  return ticks;
}

TEST(HilGolden, TickStreamLayoutIsTheDocumentedOne) {
  // Per tick: zigzag varints of the force deltas (2^-24 N), contact, flags, row hash (low, high).
  hil::Tick a, b;
  a.force_q24 = {1, -1, 64};  // zigzag 2, 1, 128 (two varint bytes)
  a.contact = true;
  a.flags = 0x22;
  a.row_hash = 0xBEEF;
  b.force_q24 = {1, -2, 0};  // deltas 0, -1, -64: zigzag 0, 1, 127
  const std::string raw = hil::RawTicks({a, b});
  const std::string want(
      "\x02\x01\x80\x01\x01\x22\xEF\xBE"
      "\x00\x01\x7F\x00\x00\x00\x00",
      15);
  EXPECT_EQ(raw, want);
}

TEST(HilGolden, EncodeDecodeRoundTripsEveryStoredField) {
  const auto ticks = SomeTicks(3000);
  const std::string gz = hil::EncodeTicks(ticks);
  ASSERT_GE(gz.size(), 18u);
  EXPECT_EQ(static_cast<unsigned char>(gz[0]), 0x1F);  // gzip, with mtime 0: the same ticks, the same bytes
  EXPECT_EQ(static_cast<unsigned char>(gz[1]), 0x8B);
  EXPECT_EQ(gz.substr(4, 4), std::string(4, '\0'));
  EXPECT_EQ(gz, hil::EncodeTicks(ticks));
  auto back = hil::DecodeTicks(gz, ticks.size());
  ASSERT_TRUE(back.has_value()) << back.error();
  ASSERT_EQ(back->size(), ticks.size());
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    const hil::Tick& t = (*back)[i];
    ASSERT_EQ(t.force_q24, ticks[i].force_q24) << "tick " << i;
    ASSERT_EQ(t.force, ticks[i].force) << "tick " << i;
    ASSERT_EQ(t.contact, ticks[i].contact) << "tick " << i;
    ASSERT_EQ(t.flags, ticks[i].flags) << "tick " << i;
    ASSERT_EQ(t.row_hash, ticks[i].row_hash) << "tick " << i;
  }
  EXPECT_EQ(hil::RawTicks(*back), hil::RawTicks(ticks));  // what ticks_sha256 is taken of
}

TEST(HilGolden, CorruptStreamErrorNamesTheByteWhereZlibStopped) {
  const auto ticks = SomeTicks(2000);
  std::string gz = hil::EncodeTicks(ticks);
  const std::size_t damaged = gz.size() / 2;
  gz[damaged] = static_cast<char>(gz[damaged] ^ 0x5A);
  auto bad = hil::DecodeTicks(gz, ticks.size());
  ASSERT_FALSE(bad.has_value());
  std::smatch m;
  ASSERT_TRUE(std::regex_search(bad.error(), m,
                                std::regex(R"(corrupt golden tick stream \(gzip\) at byte (\d+) of (\d+): .+)")))
      << bad.error();
  EXPECT_EQ(std::stoul(m[2]), gz.size());
  EXPECT_GT(std::stoul(m[1]), damaged) << bad.error();  // zlib cannot stop before it reads the damage
  EXPECT_LE(std::stoul(m[1]), gz.size()) << bad.error();

  // Cut short: all that is there is read, and the error says so.
  const std::string half = hil::EncodeTicks(ticks).substr(0, gz.size() / 2);
  auto cut = hil::DecodeTicks(half, ticks.size());
  ASSERT_FALSE(cut.has_value());
  EXPECT_EQ(cut.error(), "corrupt golden tick stream (gzip) at byte " + std::to_string(half.size()) + " of " +
                             std::to_string(half.size()) + ": truncated");
}

TEST(HilGolden, ShortStreamErrorNamesTheTickAndByte) {
  const auto ticks = SomeTicks(10);
  const std::size_t raw = hil::RawTicks(ticks).size();
  auto r = hil::DecodeTicks(hil::EncodeTicks(ticks), 11);
  ASSERT_FALSE(r.has_value());
  EXPECT_EQ(r.error(), "golden tick stream ends early: tick 10 of 11 needs byte " + std::to_string(raw) + " of " +
                           std::to_string(raw) + " (uncompressed)");
}

// A replay written by hand as palpad would, for the golden's digests.
hil::Replay HandReplay(std::size_t n) {
  hil::Replay r;
  r.csv = std::string(palpa::record::kCsvHeader) + "\n";
  for (std::size_t i = 0; i < n; ++i)
    r.csv += std::to_string(i) + "e-3,0,0,0.031,0,0,0.031," + (i % 2 ? "0.5" : "0") + ",0,-0.25,0\n";
  auto ticks = hil::ParseOutput(r.csv, "hand.csv");
  EXPECT_TRUE(ticks.has_value()) << ticks.error();
  if (ticks) r.ticks = *ticks;
  r.exit_code = 0;
  r.summary_json = R"({"ticks": 40, "end": "trace", "wake_p99_ns": 1234})";
  return r;
}

TEST(HilGolden, BlessedGoldenIsReproducedAndAChangedTickIsReported) {
  const fs::path dir = TempDir("golden");
  hil::Case c;
  c.name = "hand";
  c.trace = "traces/hand.ptb";
  c.device = "sim";
  hil::FieldSpec field;
  field.build = "build x.xyz";
  const hil::Replay r = HandReplay(40);
  std::ofstream(hil::GoldenTomlPath(dir, "hand")) << hil::GoldenToml(c, field, hil::Settings{}, r, "ab12");
  std::ofstream(hil::GoldenTicksPath(dir, "hand"), std::ios::binary) << hil::EncodeTicks(r.ticks);
  auto g = hil::ReadGolden(dir, "hand");
  ASSERT_TRUE(g.has_value()) << g.error();
  EXPECT_EQ(g->ticks, 40u);
  EXPECT_EQ(g->counters.at("ticks"), "40");
  EXPECT_EQ(g->counters.at("end"), "trace");
  EXPECT_FALSE(g->counters.contains("wake_p99_ns"));  // timing is not deterministic
  EXPECT_TRUE(hil::Reproduces(*g, r));

  // One force 2^-24 N off on tick 17: both digests change; the paragraph finds the tick.
  hil::Replay changed = r;
  changed.ticks[17].force_q24[2] += 1;
  changed.ticks[17].force[2] = changed.ticks[17].force_q24[2] / hil::kForceScale;
  EXPECT_FALSE(hil::Reproduces(*g, changed));
  EXPECT_EQ(hil::Differences(dir, "hand", *g, changed),
            "    ticks changed: 1 of 40 (forces on 1), first at tick 17; max force difference 5.96046e-08 N at tick "
            "17\n");
  // A damaged tick stream: the paragraph names the file and the byte.
  std::string gz = Slurp(hil::GoldenTicksPath(dir, "hand"));
  gz.resize(gz.size() - 3);
  std::ofstream(hil::GoldenTicksPath(dir, "hand"), std::ios::binary) << gz;
  EXPECT_EQ(hil::Differences(dir, "hand", *g, changed),
            "    " + hil::GoldenTicksPath(dir, "hand").string() + ": corrupt golden tick stream (gzip) at byte " +
                std::to_string(gz.size()) + " of " + std::to_string(gz.size()) + ": truncated\n");

  EXPECT_EQ(hil::ReadGolden(dir, "other").error(),
            "no golden " + (dir / "other.toml").string() + " (bless it: palpa hil bless other)");
  fs::remove_all(dir);
}

// ---------------------------------------------------------------- the case list

std::expected<hil::Suite, std::string> Parse(const fs::path& dir, const std::string& toml) {
  std::ofstream(dir / "cases.toml") << toml;
  return hil::LoadSuite(dir / "cases.toml");
}

const char* kFields = "[fields.a]\nbuild = \"build x.xyz\"\n";  // lines 1-2

TEST(HilSuite, ErrorsNameTheLineOfTheKeyOrCase) {
  const fs::path dir = TempDir("suite");
  const std::string at = (dir / "cases.toml").string() + ":";
  const std::string c = "[[case]]\nname = \"c\"\ntrace = \"t\"\nfield = \"a\"\nwhy = \"w\"\n";  // lines 3-7
  EXPECT_EQ(Parse(dir, std::string(kFields) + c + "device = \"falcon\"\n").error(),
            at + "8: device must be sim or virtual-falcon");
  EXPECT_EQ(Parse(dir, std::string(kFields) + c + "swap_at = 10\n").error(),
            at + "3: swap_field and swap_at (a tick ≥ 0) go together");
  EXPECT_EQ(Parse(dir, std::string(kFields) + c + "swap_field = \"b\"\nswap_at = 10\n").error(),
            at + "8: unknown field 'b'");
  EXPECT_EQ(Parse(dir, std::string(kFields) + c + c).error(), at + "8: duplicate case name c");
  EXPECT_EQ(Parse(dir, std::string(kFields) + "[[case]]\nname = \"c\"\ntrace = \"t\"\nfield = \"a\"\n").error(),
            at + "3: case c must say why (its device choice)");
  EXPECT_EQ(Parse(dir, std::string(kFields) + "[fields.b]\nbuild = \"palpa build\"\n" + c).error(),
            at + "3: fields.b needs either build = 'build POINTS ...' or blob = 'PATH'");
  EXPECT_EQ(Parse(dir, c).error(), at.substr(0, at.size() - 1) + ": no [fields] table");
  // TOML syntax: line and column.
  auto syntax = Parse(dir, std::string(kFields) + "[[case]]\nname = \"c\n");
  ASSERT_FALSE(syntax.has_value());
  EXPECT_TRUE(syntax.error().starts_with(at + "4:")) << syntax.error();
  fs::remove_all(dir);
}

TEST(HilSuite, ParsesDefaultsCasesAndSelectsByFilterNameDeviceAndMode) {
  const fs::path dir = TempDir("suite-ok");
  auto s = Parse(dir, std::string("[defaults]\nk_n_per_m = 500\nslope_factor = 3.0\n") + kFields +
                          "[[case]]\nname = \"sphere-taps\"\ntrace = \"t.ptb\"\nfield = \"a\"\nwhy = \"w\"\n"
                          "palpad = [\"--estop\", \"button:0\"]\nxfail = [\"proxy inside\"]\n"
                          "sphere = { centre_m = [0.0, 0.0, 0.001], radius_m = 0.03, validate_rms_pct = 2.0 }\n"
                          "[[case]]\nname = \"knot\"\ntrace = \"k.ptb\"\nfield = \"a\"\ndevice = \"virtual-falcon\"\n"
                          "why = \"w\"\nrealtime = false\n");
  ASSERT_TRUE(s.has_value()) << s.error();
  EXPECT_EQ(s->hil_dir, fs::absolute(dir));
  EXPECT_EQ(s->settings.k_n_per_m, 500);
  EXPECT_EQ(s->settings.max_force_n, 8);  // not in [defaults]: the built-in one
  EXPECT_EQ(s->limits.slope_factor, 3.0);
  ASSERT_EQ(s->cases.size(), 2u);
  const hil::Case& taps = s->cases[0];
  EXPECT_EQ(taps.device, "sim");
  EXPECT_EQ(taps.palpad, (std::vector<std::string>{"--estop", "button:0"}));
  EXPECT_EQ(taps.xfail, std::vector<std::string>{"proxy inside"});
  ASSERT_TRUE(taps.sphere_centre_m.has_value());
  EXPECT_EQ((*taps.sphere_centre_m)[2], 0.001);
  EXPECT_EQ(taps.validate_rms_pct, 2.0);
  EXPECT_FALSE(taps.validate_angle_deg.has_value());

  auto names = [&](std::vector<std::string> by_name, const std::string& filter, const std::string& device,
                   bool realtime) {
    hil::Selection sel;
    sel.names = std::move(by_name);
    sel.filter = filter;
    sel.device = device;
    sel.realtime = realtime;
    std::vector<std::string> out;
    for (const hil::Case* c : hil::SelectCases(*s, sel)) out.push_back(c->name);
    return out;
  };
  EXPECT_EQ(names({}, "", "", false).size(), 2u);
  EXPECT_EQ(names({}, "nope,kno", "", false), std::vector<std::string>{"knot"});
  EXPECT_EQ(names({}, "", "sim", false), std::vector<std::string>{"sphere-taps"});
  EXPECT_EQ(names({}, "", "", true), std::vector<std::string>{"sphere-taps"});
  EXPECT_EQ(names({"knot"}, "sphere", "", false), std::vector<std::string>{"knot"});
  EXPECT_TRUE(names({"kn"}, "", "", false).empty());  // names are exact
  fs::remove_all(dir);
}

// ---------------------------------------------------------------- palpad's output

TEST(HilReplay, OutputParserNamesTheLineAndHashesEachRow) {
  const std::string header = std::string(palpa::record::kCsvHeader) + "\n";
  const std::string row = "0.001,0,0,0.031,0,0,0.031,0,0,-1.5,1";
  auto ok = hil::ParseOutput(header + row + "\n\n", "out.csv");
  ASSERT_TRUE(ok.has_value()) << ok.error();
  ASSERT_EQ(ok->size(), 1u);
  EXPECT_EQ((*ok)[0].force_q24[2], -25165824);  // −1.5 N in 2^-24 N
  EXPECT_TRUE((*ok)[0].contact);
  EXPECT_EQ((*ok)[0].row_hash, hil::RowHash(row));
  EXPECT_NE(hil::RowHash(row), hil::RowHash("0.001,0,0,0.031,0,0,0.031,0,0,-1.5,0"));

  auto bad = hil::ParseOutput(header + row + "\n" + "0.002,0,x,0.031,0,0,0.031,0,0,0,0\n", "out.csv");
  ASSERT_FALSE(bad.has_value());
  EXPECT_EQ(bad.error(), "out.csv:3: field 3 'x' is not a finite number");
  auto wrong = hil::ParseOutput("t,x\n" + row + "\n", "out.csv");
  ASSERT_FALSE(wrong.has_value());
  EXPECT_TRUE(wrong.error().starts_with("out.csv:1: expected palpad's CSV header")) << wrong.error();
}

TEST(HilTiming, NearestRankPercentilesLeaveOutRowsWithoutADeadline) {
  std::vector<std::int64_t> ns = {-1};
  for (std::int64_t us = 100; us >= 1; --us) ns.push_back(us * 1000);
  const hil::Percentiles p = hil::Figures(ns);
  EXPECT_EQ(p.count, 100u);
  EXPECT_EQ(p.p50, 50.0);
  EXPECT_EQ(p.p99, 99.0);
  EXPECT_EQ(p.p999, 100.0);
  EXPECT_EQ(p.max, 100.0);
  EXPECT_EQ(hil::Figures({-1, -1}).count, 0u);
}

// ---------------------------------------------------------------- invariants

// φ of a sphere of radius 30 mm at the origin, 0.1 mm voxels: the truth the checks are held to.
class Sphere final : public hil::PhiField {
 public:
  double Phi(const Eigen::Vector3d& x_m) const override { return x_m.norm() - 0.03; }
  double voxel_m() const override { return 1e-4; }
};

constexpr double kK = 800, kMaxForce = 8;

// One tick a millisecond on the z axis: HIP and proxy heights (m), force from the spring (or given).
struct Row {
  double hip_z, proxy_z;
  double force_z = std::nan("");
};

std::vector<hil::Tick> Ticks(const std::vector<Row>& rows) {
  std::vector<hil::Tick> out;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    hil::Tick t;
    t.t_s = static_cast<double>(i) * 1e-3;
    t.hip = {0, 0, rows[i].hip_z};
    t.proxy = {0, 0, rows[i].proxy_z};
    t.force[2] = std::isnan(rows[i].force_z) ? kK * (rows[i].proxy_z - rows[i].hip_z) : rows[i].force_z;
    t.contact = t.force[2] != 0;
    out.push_back(t);
  }
  return out;
}

// Outside, pressed 0.2 mm in with the proxy on the surface, and out again: a clean contact.
const std::vector<Row> kClean = {{0.031, 0.031},  {0.0305, 0.0305}, {0.030, 0.030}, {0.0299, 0.030},
                                 {0.0298, 0.030}, {0.0299, 0.030},  {0.030, 0.030}, {0.0305, 0.0305}};

hil::Metrics MeasureOn(const std::vector<Row>& rows, const hil::Case& c = {}) {
  return hil::Measure(Ticks(rows), c, Sphere(), nullptr, kK, kMaxForce, hil::Limits{});
}

TEST(HilInvariants, CleanContactPasses) {
  const hil::Metrics m = MeasureOn(kClean);
  EXPECT_TRUE(m.failures.empty()) << m.failures.front();
  EXPECT_EQ(m.contact_ticks, 3u);
  EXPECT_NEAR(m.max_force_n, 0.16, 1e-9);
  EXPECT_NEAR(m.deepest_hip_mm, 0.2, 1e-9);
  EXPECT_NEAR(m.min_proxy_phi_voxels, 0, 1e-9);
}

TEST(HilInvariants, ProxyInsideTheSphereFails) {
  std::vector<Row> rows = kClean;
  rows[4] = {0.0298, 0.0299};  // the proxy one voxel inside, the spring's force with it
  const hil::Metrics m = MeasureOn(rows);
  ASSERT_FALSE(m.failures.empty());
  EXPECT_EQ(m.failures[0], "proxy inside the object at tick 4: φ = -1.0000 voxel < −0.26 voxel");
  EXPECT_NEAR(m.min_proxy_phi_voxels, -1.0, 1e-6);
}

TEST(HilInvariants, ForceDroppedWithTheHipInsideAndOverTheClampFail) {
  std::vector<Row> drop = kClean;
  drop[5] = {0.0298, 0.030, 0.0};  // still 2 voxels inside: the force may not vanish
  const hil::Metrics m = MeasureOn(drop);
  auto has = [&](const std::string& s) {
    return std::ranges::any_of(m.failures, [&](const std::string& f) { return f.starts_with(s); });
  };
  EXPECT_TRUE(has("force dropped to zero with the HIP inside 1 times, first at tick 5"))
      << ::testing::PrintToString(m.failures);
  EXPECT_TRUE(has("force step 0.1600 N at tick 5 exceeds the slope limit")) << ::testing::PrintToString(m.failures);
  std::vector<Row> hard = kClean;
  hard[4].force_z = 9.0;
  EXPECT_EQ(MeasureOn(hard).failures.front(), "force 9.000000 N exceeds the clamp 8 N");
}

TEST(HilInvariants, SphereValidationFailsAgainstTheWrongRadius) {
  hil::Case c;
  c.sphere_centre_m = std::array<double, 3>{0, 0, 0};
  c.sphere_radius_m = 0.03;
  c.validate_rms_pct = 2.0;
  hil::Metrics m = MeasureOn(kClean, c);
  EXPECT_TRUE(m.analytic);
  EXPECT_NEAR(m.rms_error_n, 0, 1e-9);
  EXPECT_TRUE(m.failures.empty()) << m.failures.front();
  c.sphere_radius_m = 0.0301;  // 0.1 mm too large: every contact force 0.08 N short
  m = MeasureOn(kClean, c);
  ASSERT_EQ(m.failures.size(), 1u);
  EXPECT_TRUE(m.failures[0].starts_with("Fig. 9 validation: force RMS error")) << m.failures[0];
}

TEST(HilInvariants, RunChecksCatchEstopForceExitCodeAndKnownFailures) {
  hil::Replay r;
  r.ticks = Ticks(kClean);
  r.exit_code = 1;
  r.stderr_text = "palpad: device fault\nstopped\n";
  std::vector<hil::TimingRow> timing(kClean.size());
  timing[3].flags = palpa::record::kFlagEstop;  // a force on an e-stop tick
  timing[6].flags = palpa::record::kFlagEstop;  // none here
  hil::Case c;
  c.palpad = {"--estop", "button:0"};
  hil::Metrics m;
  EXPECT_EQ(hil::CheckRun(r, timing, c, m), 2u);
  ASSERT_EQ(m.failures.size(), 2u);
  EXPECT_EQ(m.failures[0], "palpad exited 1 (expected 0): palpad: device fault | stopped | ");
  EXPECT_EQ(m.failures[1], "e-stop asserted on 2 ticks, 1 of them with non-zero force");

  c.xfail = {"e-stop asserted", "never happens"};
  const hil::KnownFailures k = hil::SetAsideKnown(c, m);
  EXPECT_EQ(k.known, std::vector<std::string>{"e-stop asserted on 2 ticks, 1 of them with non-zero force"});
  EXPECT_EQ(k.gone, std::vector<std::string>{"never happens"});
  EXPECT_EQ(m.failures.size(), 1u);

  hil::Metrics none;
  r.exit_code = 0;
  EXPECT_EQ(hil::CheckRun(r, std::vector<hil::TimingRow>(kClean.size()), c, none), 0u);
  EXPECT_EQ(none.failures, std::vector<std::string>{"the case wires an e-stop but no tick saw it asserted"});
}

// ---------------------------------------------------------------- field probe

TEST(HilFieldProbe, ReadsTheCommittedBlobOnceAndNamesABadOne) {
  hil::FieldProbes probes;
  const fs::path blob = fs::path(PALPA_SOURCE_DIR) / "hil" / "fields" / "open-plate-cut.palpa";
  auto f = probes.Get("cut", blob);
  ASSERT_TRUE(f.has_value()) << f.error();
  EXPECT_GT((*f)->voxel_m(), 0);
  EXPECT_TRUE(std::isfinite((*f)->Phi(Eigen::Vector3d(0, 0, 0))));
  EXPECT_EQ(*probes.Get("cut", "/not/read/again"), *f);

  const fs::path dir = TempDir("probe");
  std::string bytes = Slurp(blob);
  bytes[bytes.size() - 5] = static_cast<char>(bytes[bytes.size() - 5] ^ 1);  // a payload byte: the CRC fails
  std::ofstream(dir / "bad.palpa", std::ios::binary) << bytes;
  auto bad = probes.Get("bad", dir / "bad.palpa");
  ASSERT_FALSE(bad.has_value());
  EXPECT_TRUE(bad.error().starts_with((dir / "bad.palpa").string() + ": ")) << bad.error();
  EXPECT_NE(bad.error().find("byte"), std::string::npos) << bad.error();
  auto missing = probes.Get("missing", dir / "missing.palpa");
  ASSERT_FALSE(missing.has_value());
  EXPECT_NE(missing.error().find((dir / "missing.palpa").string()), std::string::npos) << missing.error();
  fs::remove_all(dir);
}

}  // namespace
