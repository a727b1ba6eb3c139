#include "palpa/servo/servo_loop.h"

#include <gtest/gtest.h>

#include <cstdlib>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numbers>
#include <sstream>
#include <thread>

#include "palpa/device_sim/sim_device.h"
#include "palpa/record/latency_histogram.h"
#include "palpa/servo/report.h"
#include "sphere_fixture.h"

namespace palpa::servo {
namespace {

using device::HipReading;
using device::IoStatus;
using firmware_test::Norm;
using firmware_test::SphereField;

constexpr double kK = 800;  // N/m, ProxyConfig default

proxy::ProxyParams Params(double voxel_m, double max_force_n = 8) {
  proxy::ProxyConfig c;
  c.k_n_per_m = kK;
  c.max_force_n = max_force_n;
  auto p = proxy::MakeProxyParams(c, voxel_m);
  if (!p) {  // without parameters nothing below is meaningful: stop rather than read an empty expected
    ADD_FAILURE() << "MakeProxyParams: " << p.error();
    std::abort();
  }
  return *p;
}

std::array<double, 3> Sub(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}

double AngleDeg(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  const double c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (Norm(a) * Norm(b));
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

std::string ReadAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// Replays `keys` at `rate_hz`, fast, and returns the loop's results through the callback.
struct Replay {
  Replay(const SphereField& field, std::vector<trace::TraceSample> samples, double max_force_n = 8,
         std::size_t capacity = 0, double rate_hz = 1000)
      : device(std::move(samples), rate_hz),
        loop(field.view(), Params(field.voxel_m(), max_force_n), device, capacity ? capacity : device.TickCount(),
             stop) {}
  std::atomic<bool> stop{false};
  device_sim::SimDevice device;
  ServoLoop loop;
};

TEST(ServoLoop, HipHeldTwoMillimetresInsideGivesHookeForceAlongTheNormal) {
  const SphereField field;
  const double r = field.radius_m();
  // Off-axis direction so that all three gradient components matter.
  for (const std::array<double, 3> dir : {std::array<double, 3>{1, 2, 2}, {-0.3, 0.5, -0.8}, {0, 0, 1}}) {
    Replay replay(
        field, firmware_test::TraceFromKeys(field, {{0.0, r + 3e-3, dir}, {1.0, r - 2e-3, dir}, {2.0, r - 2e-3, dir}}));
    ASSERT_EQ(replay.loop.Run(/*fast=*/true, 1000), RunEnd::kEnded);
    const LogRow& last = replay.loop.rows().back();
    ASSERT_TRUE(last.contact);
    const double f = Norm(last.force_n);
    const double expected = kK * 2e-3;  // 1.6 N
    const double error_pct = 100.0 * std::abs(f - expected) / expected;
    const auto radial = Sub(last.hip_m, field.center_m());
    const double angle = AngleDeg(last.force_n, radial);
    std::printf(
        "[ measured ] dir (%g,%g,%g): |f| = %.6f N (k·2 mm = %.3f N, error %.3f %%), angle to normal %.4f deg\n",
        dir[0], dir[1], dir[2], f, expected, error_pct, angle);
    EXPECT_LT(error_pct, 5.0);
    EXPECT_LT(angle, 2.0);
    // The proxy sits on the surface (the trilinear zero set is within a few hundredths of a voxel).
    EXPECT_NEAR(Norm(Sub(last.proxy_m, field.center_m())), r, 0.05 * field.voxel_m());
  }
}

TEST(ServoLoop, HipInFreeSpaceGivesExactlyZeroForce) {
  const SphereField field;
  const double r = field.radius_m();
  Replay replay(field, firmware_test::TraceFromKeys(field, {{0.0, r + 3e-3, {1, 0, 0}}, {1.0, r + 0.5e-3, {1, 1, 0}}}));
  ASSERT_EQ(replay.loop.Run(true, 1000), RunEnd::kEnded);
  ASSERT_EQ(replay.loop.rows().size(), 1001u);
  for (const LogRow& row : replay.loop.rows()) {
    EXPECT_FALSE(row.contact);
    EXPECT_EQ(row.force_n, (std::array<double, 3>{0.0, 0.0, 0.0}));
    for (std::size_t a = 0; a < 3; ++a)
      EXPECT_NEAR(row.proxy_m[a], row.hip_m[a], field.voxel_m() / 65536);  // proxy = HIP
  }
  EXPECT_EQ(replay.loop.counters().contact_ticks, 0u);
  EXPECT_EQ(replay.loop.counters().max_force_n, 0.0);
  EXPECT_EQ(replay.loop.counters().max_penetration_m, 0.0);
}

TEST(ServoLoop, CountersAgreeWithTheLog) {
  const SphereField field;
  // 1 N clamp below k·2 mm = 1.6 N, so clamped ticks occur.
  Replay replay(field, firmware_test::PressSlideLeaveTrace(field), /*max_force_n=*/1.0);
  ASSERT_EQ(replay.loop.Run(true, 1000), RunEnd::kEnded);
  const ServoCounters& c = replay.loop.counters();
  const auto rows = replay.loop.rows();
  ASSERT_EQ(c.ticks, rows.size());
  EXPECT_EQ(c.ticks, replay.device.TickCount());
  std::uint64_t contact = 0, surely_clamped = 0, maybe_clamped = 0;
  double max_f = 0, max_pen = 0;
  for (const LogRow& row : rows) {
    const double f = Norm(row.force_n);
    const double pen = row.contact ? Norm(Sub(row.proxy_m, row.hip_m)) : 0.0;
    contact += row.contact ? 1 : 0;
    // Within a few Q16.16 LSB of the 1 N limit the clamp decision is the fixed-point one: bracket it.
    surely_clamped += kK * pen > 1.0 + 1e-4 ? 1 : 0;
    maybe_clamped += f > 1.0 - 1e-4 ? 1 : 0;
    EXPECT_LT(f, 1.0 + 3e-5) << "clamped with direction kept, t = " << row.t_s;
    max_f = std::max(max_f, f);
    max_pen = std::max(max_pen, pen);
    EXPECT_EQ(row.contact, f > 0) << "contact exactly when a force is written, t = " << row.t_s;
  }
  EXPECT_EQ(c.contact_ticks, contact);
  EXPECT_GE(c.force_clamps, surely_clamped);
  EXPECT_LE(c.force_clamps, maybe_clamped);
  EXPECT_LE(maybe_clamped - surely_clamped, 5u);
  EXPECT_GT(c.force_clamps, 1000u);
  EXPECT_LT(c.force_clamps, c.contact_ticks);
  EXPECT_DOUBLE_EQ(c.max_force_n, max_f);
  // The counter uses the proxy's integer length (floored), the rows the metres: 2 LSB apart at most.
  EXPECT_NEAR(c.max_penetration_m, max_pen, 2 * field.voxel_m() / 65536);
  EXPECT_NEAR(c.max_penetration_m, 2e-3, 0.1e-3);
  EXPECT_EQ(c.device_errors, 0u);
  EXPECT_EQ(c.dropped_rows, 0u);
  EXPECT_EQ(c.overruns, 0u);
  // Run always ends with zero force on the device.
  EXPECT_EQ(replay.device.last_force_n(), (std::array<double, 3>{0.0, 0.0, 0.0}));
  EXPECT_EQ(replay.device.writes(), c.ticks + 2);  // every tick, the kEnd tick's zero, the run's final zero
}

TEST(ServoLoop, FastModeIsDeterministic) {
  const SphereField field;
  const std::string dir = ::testing::TempDir();
  const std::string a = dir + "/palpa_fast_a.csv", b = dir + "/palpa_fast_b.csv";
  for (const std::string& path : {a, b}) {
    Replay replay(field, firmware_test::PressSlideLeaveTrace(field));
    ASSERT_EQ(replay.loop.Run(true, 1000), RunEnd::kEnded);
    ASSERT_TRUE(WriteCsvAtomic(path, replay.loop.rows()).has_value());
  }
  const std::string bytes_a = ReadAll(a), bytes_b = ReadAll(b);
  EXPECT_GT(bytes_a.size(), 10001u * 20);
  EXPECT_EQ(bytes_a, bytes_b);
  EXPECT_TRUE(bytes_a.starts_with(std::string(kCsvHeader) + "\n"));
  std::remove(a.c_str());
  std::remove(b.c_str());
}

TEST(ServoLoop, FullLogCountsDroppedRowsAndNeverGrows) {
  const SphereField field;
  Replay replay(field, firmware_test::PressSlideLeaveTrace(field), 8, /*capacity=*/100);
  ASSERT_EQ(replay.loop.Run(true, 1000), RunEnd::kEnded);
  EXPECT_EQ(replay.loop.rows().size(), 100u);
  EXPECT_EQ(replay.loop.tick_ns().size(), 100u);
  EXPECT_EQ(replay.loop.counters().ticks, 10001u);
  EXPECT_EQ(replay.loop.counters().dropped_rows, 10001u - 100u);
}

TEST(ServoLoop, TickTimingOnTheSphere) {
  const SphereField field;
  Replay replay(field, firmware_test::PressSlideLeaveTrace(field));
  ASSERT_EQ(replay.loop.Run(true, 1000), RunEnd::kEnded);
  const ServoSummary s = Summarize(replay.loop, true, 1000);
  std::vector<std::int64_t> contact_ns;
  const std::span<const LogRow> rows = replay.loop.rows();  // snapshots of the ring: take them once
  const std::span<const std::int64_t> tick_ns = replay.loop.tick_ns();
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (rows[i].contact) contact_ns.push_back(tick_ns[i]);
  }
  std::printf(
      "[ measured ] %llu ticks (%llu in contact): median tick %lld ns, p99 %lld ns; contact ticks: median %lld ns, p99 "
      "%lld ns\n",
      static_cast<unsigned long long>(s.ticks), static_cast<unsigned long long>(s.contact_ticks),
      static_cast<long long>(s.median_tick_ns), static_cast<long long>(s.p99_tick_ns),
      static_cast<long long>(record::PercentileOfSamples(contact_ns, 0.5)),
      static_cast<long long>(record::PercentileOfSamples(contact_ns, 0.99)));
  EXPECT_GT(s.median_tick_ns, 0);
  EXPECT_LE(s.median_tick_ns, s.p99_tick_ns);
  EXPECT_LT(s.median_tick_ns, 1'000'000) << "a tick must fit a 1 kHz period";
}

// A device with a scripted failure: the HIP presses from `from_m` to `to_m` over 10 ticks (a proxy
// started inside would stay with the HIP) and holds; after `good_ticks` the chosen transfer fails.
class ScriptedDevice final : public device::HapticDevice {
 public:
  ScriptedDevice(std::array<double, 3> from_m, std::array<double, 3> to_m, int good_ticks, bool fail_write)
      : from_m_(from_m), to_m_(to_m), good_ticks_(good_ticks), fail_write_(fail_write) {}
  std::array<double, 3> last_force_n{};

 private:
  IoStatus DoRead(HipReading& out) override {
    if (!fail_write_ && reads_ >= good_ticks_) return IoStatus::kError;
    const double u = std::min(1.0, reads_ / 10.0);
    for (std::size_t a = 0; a < 3; ++a) out.hip_m[a] = from_m_[a] + (to_m_[a] - from_m_[a]) * u;
    ++reads_;
    return IoStatus::kOk;
  }
  IoStatus DoWrite(const std::array<double, 3>& f) override {
    last_force_n = f;
    const bool zero = f == std::array<double, 3>{0.0, 0.0, 0.0};
    if (fail_write_ && reads_ > good_ticks_ && !zero) return IoStatus::kError;
    return IoStatus::kOk;
  }
  std::array<double, 3> from_m_, to_m_;
  int good_ticks_;
  bool fail_write_;
  int reads_ = 0;
};

ScriptedDevice Pressing(const SphereField& field, int good_ticks, bool fail_write) {
  return ScriptedDevice(field.PointAt(field.radius_m() + 1e-3, {0, 1, 0}),
                        field.PointAt(field.radius_m() - 1e-3, {0, 1, 0}), good_ticks, fail_write);
}

TEST(ServoLoop, ReadErrorWritesZeroForceCountsAndStops) {
  const SphereField field;
  ScriptedDevice dev = Pressing(field, 20, /*fail_write=*/false);
  std::atomic<bool> stop{false};
  ServoLoop loop(field.view(), Params(field.voxel_m()), dev, 100, stop);
  EXPECT_EQ(loop.Run(true, 1000), RunEnd::kDeviceError);
  EXPECT_EQ(loop.counters().ticks, 20u);
  EXPECT_EQ(loop.counters().device_errors, 1u);
  EXPECT_GT(loop.counters().contact_ticks, 0u);
  EXPECT_EQ(dev.last_force_n, (std::array<double, 3>{0.0, 0.0, 0.0}));
}

TEST(ServoLoop, WriteErrorWritesZeroForceCountsAndStops) {
  const SphereField field;
  ScriptedDevice dev = Pressing(field, 20, /*fail_write=*/true);
  std::atomic<bool> stop{false};
  ServoLoop loop(field.view(), Params(field.voxel_m()), dev, 100, stop);
  EXPECT_EQ(loop.Run(true, 1000), RunEnd::kDeviceError);
  EXPECT_EQ(loop.counters().ticks, 21u);  // the failed tick is logged: it computed a force
  EXPECT_EQ(loop.counters().device_errors, 1u);
  EXPECT_EQ(dev.last_force_n, (std::array<double, 3>{0.0, 0.0, 0.0}));
}

TEST(ServoLoop, StopFlagSetBeforeRunTicksNothingAndWritesZero) {
  const SphereField field;
  Replay replay(field, firmware_test::PressSlideLeaveTrace(field));
  replay.device.Write({1.0, 1.0, 1.0});
  replay.stop = true;
  EXPECT_EQ(replay.loop.Run(true, 1000), RunEnd::kStopped);
  EXPECT_EQ(replay.loop.counters().ticks, 0u);
  EXPECT_EQ(replay.device.last_force_n(), (std::array<double, 3>{0.0, 0.0, 0.0}));
}

TEST(ServoLoop, StopFlagEndsAPacedRun) {
  const SphereField field;
  Replay replay(field, firmware_test::PressSlideLeaveTrace(field));  // 10 s if not stopped
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    replay.stop = true;
  });
  const auto t0 = std::chrono::steady_clock::now();
  const RunEnd end = replay.loop.Run(false, 1000);
  const auto elapsed = std::chrono::steady_clock::now() - t0;
  stopper.join();
  EXPECT_EQ(end, RunEnd::kStopped);
  EXPECT_LT(elapsed, std::chrono::seconds(5));
  EXPECT_GT(replay.loop.counters().ticks, 0u);
  EXPECT_LT(replay.loop.counters().ticks, 5000u);
  EXPECT_EQ(replay.device.last_force_n(), (std::array<double, 3>{0.0, 0.0, 0.0}));
}

TEST(ServoLoop, PacedRunKeepsAbsoluteDeadlines) {
  const SphereField field;
  const double r = field.radius_m();
  // 0.1 s at 2 kHz: 201 ticks, 200 periods. Bunched or early ticks would finish sooner.
  Replay replay(field, firmware_test::TraceFromKeys(field, {{0.0, r + 1e-3, {0, 0, 1}}, {0.1, r - 1e-3, {0, 0, 1}}}), 8,
                0, 2000);
  ASSERT_EQ(replay.device.TickCount(), 201u);
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(replay.loop.Run(false, 2000), RunEnd::kEnded);
  const double elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("[ measured ] paced 2 kHz: 201 ticks in %.4f s, %llu overruns\n", elapsed_s,
              static_cast<unsigned long long>(replay.loop.counters().overruns));
  EXPECT_EQ(replay.loop.counters().ticks, 201u);
  EXPECT_GE(elapsed_s, 0.0995);
  EXPECT_LT(elapsed_s, 2.0);
}

TEST(ServoLoop, PacedRunRefusesAnInvalidRate) {
  const SphereField field;
  Replay replay(field, firmware_test::PressSlideLeaveTrace(field));
  EXPECT_EQ(replay.loop.Run(false, 0.5), RunEnd::kInvalidRate);
  EXPECT_EQ(replay.loop.Run(false, std::numeric_limits<double>::quiet_NaN()), RunEnd::kInvalidRate);
  EXPECT_EQ(replay.loop.counters().ticks, 0u);
}

}  // namespace
}  // namespace palpa::servo
