// The servo loop's runtime behaviour on simulated time (an injected clock): pacing on absolute
// deadlines, wake-up latency and compute time in the histograms, the overrun policy (skip, never
// bunch; N consecutive → zero force and the fault state), the e-stop (zero force in the same tick,
// debounced release, proxy reset to the HIP, force ramp — checked against Hooke's law), the tick
// line (one toggle per tick, at the wake-up), the watchdog with stalling devices, and the
// telemetry drain (the CSV it streams equals the one written from the whole log).

#include <gtest/gtest.h>

#include <cstdlib>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <thread>

#include "palpa/device_sim/sim_device.h"
#include "palpa/gpio_sim/sim_gpio.h"
#include "palpa/io/atomic_file.h"
#include "palpa/servo/report.h"
#include "palpa/servo/servo_loop.h"
#include "palpa/servo/telemetry_drain.h"
#include "palpa/servo/watchdog.h"
#include "runtime_fixtures.h"
#include "sphere_fixture.h"

namespace palpa::servo {
namespace {

using firmware_test::FakeClock;
using firmware_test::Norm;
using firmware_test::SphereField;
using firmware_test::TickDevice;
using gpio_sim::LevelSample;

constexpr double kK = 800;                   // N/m (ProxyConfig default)
constexpr std::int64_t kPeriod = 1'000'000;  // 1 kHz, ns

proxy::ProxyParams Params(double voxel_m) {
  auto p = proxy::MakeProxyParams(proxy::ProxyConfig{}, voxel_m);
  if (!p) {  // without parameters nothing below is meaningful: stop rather than read an empty expected
    ADD_FAILURE() << "MakeProxyParams: " << p.error();
    std::abort();
  }
  return *p;
}

std::string ReadAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// HIPs along +y through the sphere's surface: `depth_m(n)` below the surface at tick n.
template <typename Depth>
std::vector<std::array<double, 3>> Hips(const SphereField& field, std::size_t n, Depth depth_m) {
  std::vector<std::array<double, 3>> hips(n);
  for (std::size_t i = 0; i < n; ++i) hips[i] = field.PointAt(field.radius_m() - depth_m(i), {0, 1, 0});
  return hips;
}

// Free space: 5 mm outside.
std::vector<std::array<double, 3>> FreeHips(const SphereField& field, std::size_t n) {
  return Hips(field, n, [](std::size_t) { return -5e-3; });
}

// ---------------------------------------------------------------- pacing and overruns

TEST(RuntimeLoop, PacedTicksWakeOnAbsoluteDeadlinesAndHistogramsAreExact) {
  const SphereField field;
  FakeClock clock;
  const std::int64_t t0 = clock.now_ns;
  // Wake-up latencies 0..99 µs (one per tick), compute 3 µs per tick.
  for (int i = 0; i < 100; ++i) clock.wake_latency_ns.push_back(i * 1000);
  TickDevice device(clock, FreeHips(field, 100), std::vector<std::int64_t>(100, 3000));
  std::atomic<bool> stop{false};
  ServoConfig c;
  c.clock = &clock;
  ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);
  ASSERT_EQ(loop.Run(false, 1000), RunEnd::kEnded);
  ASSERT_EQ(loop.counters().ticks, 100u);
  EXPECT_EQ(loop.counters().overruns, 0u);
  // Deadline n is t0 + (n+1)·period whatever the latency: absolute, so nothing accumulates.
  ASSERT_GE(clock.deadlines().size(), 100u);
  for (std::size_t n = 0; n < 100; ++n)
    EXPECT_EQ(clock.deadlines()[n], t0 + static_cast<std::int64_t>(n + 1) * kPeriod) << n;
  const WakeLatencyHistogram& w = loop.wake_latency();
  EXPECT_EQ(w.count(), 100u);
  EXPECT_EQ(w.PercentileNs(0.5), 49'000);  // 50th of 0..99 µs
  EXPECT_EQ(w.PercentileNs(0.99), 98'000);
  EXPECT_EQ(w.max_ns(), 99'000);
  EXPECT_EQ(loop.compute_time().PercentileNs(0.5), 3000);
  EXPECT_EQ(loop.compute_time().max_ns(), 3000);
  // The samples carry the same numbers.
  std::int64_t latency_sum = 0;
  loop.telemetry().ForEachQueued([&](const TelemetrySample& s) {
    latency_sum += s.wake_latency_ns;
    EXPECT_EQ(s.compute_ns, 3000);
  });
  EXPECT_EQ(latency_sum, 99 * 100 / 2 * 1000);
}

TEST(RuntimeLoop, OverrunSkipsToTheNextDeadlineAndNeverBunchesTicks) {
  const SphereField field;
  FakeClock clock;
  const std::int64_t t0 = clock.now_ns;
  // Tick 5 computes for 2.5 periods; the others take 10 µs.
  std::vector<std::int64_t> cost(20, 10'000);
  cost[5] = 2'500'000;
  TickDevice device(clock, FreeHips(field, 20), cost);
  std::atomic<bool> stop{false};
  ServoConfig c;
  c.clock = &clock;
  ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);
  ASSERT_EQ(loop.Run(false, 1000), RunEnd::kEnded);
  EXPECT_EQ(loop.counters().overruns, 1u);
  EXPECT_EQ(loop.counters().max_consecutive_overruns, 1u);
  EXPECT_EQ(loop.state(), LoopState::kRunning);
  // Tick 5 woke at t0 + 6 ms and ended at t0 + 8.5 ms: deadlines 7 and 8 ms are skipped (not run
  // back to back), tick 6 wakes at 9 ms, and the grid t0 + n·period is kept.
  const auto& d = clock.deadlines();
  EXPECT_EQ(d[5], t0 + 6 * kPeriod);
  EXPECT_EQ(d[6], t0 + 9 * kPeriod);
  for (std::size_t n = 7; n < 20; ++n) EXPECT_EQ(d[n], t0 + static_cast<std::int64_t>(n + 3) * kPeriod);
  int flagged = 0;
  loop.telemetry().ForEachQueued([&](const TelemetrySample& s) {
    if ((s.flags & kFlagOverrun) != 0) {
      ++flagged;
      EXPECT_EQ(s.tick, 5u);
    }
  });
  EXPECT_EQ(flagged, 1);
}

TEST(RuntimeLoop, ConsecutiveOverrunsLatchTheFaultAndZeroTheForce) {
  const SphereField field;
  FakeClock clock;
  // Pressing 1 mm in, so the force before the fault is not zero; from tick 30 every tick takes
  // 1.2 periods.
  std::vector<std::int64_t> cost(200, 10'000);
  for (std::size_t i = 30; i < 200; ++i) cost[i] = 1'200'000;
  TickDevice device(
      clock, Hips(field, 200, [](std::size_t n) { return std::min(1e-3, -1e-3 + 2e-4 * static_cast<double>(n)); }),
      cost);
  std::atomic<bool> stop{false};
  ServoConfig c;
  c.clock = &clock;
  c.overrun_fault_limit = 4;
  ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);
  EXPECT_EQ(loop.Run(false, 1000), RunEnd::kOverrunFault);
  EXPECT_EQ(loop.state(), LoopState::kFault);
  EXPECT_EQ(loop.fault(), FaultCause::kOverruns);
  EXPECT_EQ(loop.counters().ticks, 34u) << "ticks 30..33 overran: the 4th latches the fault";
  EXPECT_EQ(loop.counters().overruns, 4u);
  EXPECT_EQ(loop.counters().max_consecutive_overruns, 4u);
  ASSERT_GE(device.writes().size(), 35u);
  EXPECT_GT(Norm(device.writes()[33]), 0.5) << "in contact when the fault came";
  EXPECT_EQ(device.writes().back(), (std::array<double, 3>{0, 0, 0}));
  // A latched fault stays: Step writes zero and ticks nothing.
  EXPECT_EQ(loop.Step(), StepResult::kFault);
  EXPECT_EQ(loop.counters().ticks, 34u);
  EXPECT_EQ(device.writes().back(), (std::array<double, 3>{0, 0, 0}));
}

TEST(RuntimeLoop, OverrunsThatDoNotFollowEachOtherDoNotFault) {
  const SphereField field;
  FakeClock clock;
  std::vector<std::int64_t> cost(100, 10'000);
  for (std::size_t i = 10; i < 100; i += 2) cost[i] = 1'500'000;  // every other tick overruns
  TickDevice device(clock, FreeHips(field, 100), cost);
  std::atomic<bool> stop{false};
  ServoConfig c;
  c.clock = &clock;
  c.overrun_fault_limit = 2;
  ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);
  EXPECT_EQ(loop.Run(false, 1000), RunEnd::kEnded);
  EXPECT_EQ(loop.counters().overruns, 45u);
  EXPECT_EQ(loop.counters().max_consecutive_overruns, 1u);
}

// ---------------------------------------------------------------- e-stop and ramp

// HIP per tick: 1 mm outside → 1 mm inside over ticks 0..9, held to tick 149; out to 2 mm outside
// at 150..159 (during the e-stop); back in to 1 mm inside over 240..249, held to the end (400).
double EstopScenarioDepth(std::size_t n) {
  auto lerp = [](double a, double b, double u) { return a + (b - a) * std::clamp(u, 0.0, 1.0); };
  const auto t = static_cast<double>(n);
  if (n < 150) return lerp(-1e-3, 1e-3, t / 9.0);
  if (n < 240) return lerp(1e-3, -2e-3, (t - 150) / 9.0);
  return lerp(-2e-3, 1e-3, (t - 240) / 9.0);
}

struct EstopRun {
  explicit EstopRun(const SphereField& field, std::vector<LevelSample> script, bool active_high = true)
      : input(clock, std::move(script), /*initial=*/!active_high), device(clock, Hips(field, 400, EstopScenarioDepth)) {
    ServoConfig c;
    c.clock = &clock;
    c.telemetry_capacity = 1000;
    c.estop = &input;
    c.estop_active_high = active_high;
    c.estop_release_ticks = 5;
    c.ramp_ticks = 50;
    loop = std::make_unique<ServoLoop>(field.view(), Params(field.voxel_m()), device, c, stop);
  }
  // Tick n wakes at t0 + (n+1)·period: a script step at Wake(n) is first seen by tick n.
  static std::int64_t Wake(std::int64_t t0, std::int64_t n) { return t0 + (n + 1) * kPeriod; }

  FakeClock clock;
  gpio_sim::SimInput input;
  TickDevice device;
  std::atomic<bool> stop{false};
  std::unique_ptr<ServoLoop> loop;
};

TEST(RuntimeLoop, EstopZeroesTheForceInTheSameTickAndRampsBackInAfterADebouncedRelease) {
  const SphereField field;
  const std::int64_t t0 = FakeClock().now_ns;
  // Asserted (high) at tick 100, a 2-tick glitch low at 180 (not a release: debounce 5), released
  // for good at tick 200.
  EstopRun run(field, {{EstopRun::Wake(t0, 100), true},
                       {EstopRun::Wake(t0, 180), false},
                       {EstopRun::Wake(t0, 182), true},
                       {EstopRun::Wake(t0, 200), false}});
  ASSERT_EQ(run.loop->Run(false, 1000), RunEnd::kEnded);
  const std::span<const LogRow> rows = run.loop->rows();
  ASSERT_EQ(rows.size(), 400u);
  const double hooke = kK * 1e-3;  // 0.8 N at 1 mm (Hooke, paper eq. 10)

  EXPECT_NEAR(Norm(rows[99].force_n), hooke, 0.03 * hooke) << "pressing 1 mm before the e-stop";
  for (std::size_t n = 100; n < 204; ++n) {
    EXPECT_EQ(rows[n].force_n, (std::array<double, 3>{0, 0, 0})) << "e-stopped tick " << n;
    EXPECT_FALSE(rows[n].contact);
  }
  EXPECT_EQ(run.loop->counters().estop_events, 1u) << "a glitch shorter than the debounce is no release";
  EXPECT_EQ(run.loop->counters().estop_ticks, 104u);
  // Tick 204 is the 5th released read: the proxy restarts at the HIP (2 mm outside, free space).
  for (std::size_t a = 0; a < 3; ++a) EXPECT_NEAR(rows[204].proxy_m[a], rows[204].hip_m[a], field.voxel_m() / 65536);
  // The press at 240..249 meets the surface; from ~250 the HIP is held 1 mm in. The ramp started
  // at tick 204 (scale (n − 203)/50) and ends at tick 253: Hooke's force times the scale.
  for (std::size_t n = 250; n < 253; ++n) {
    const double scale = static_cast<double>(n - 203) / 50.0;
    EXPECT_NEAR(Norm(rows[n].force_n), scale * hooke, 0.03 * hooke) << n;
  }
  for (std::size_t n = 260; n < 400; ++n) EXPECT_NEAR(Norm(rows[n].force_n), hooke, 0.03 * hooke) << n;
  EXPECT_EQ(run.loop->state(), LoopState::kRunning);
}

TEST(RuntimeLoop, EstopActiveLowAndReadErrorsAreFailSafe) {
  const SphereField field;
  const std::int64_t t0 = FakeClock().now_ns;
  // Active low: the line is high (released) at first, low (asserted) from tick 100.
  EstopRun run(field, {{EstopRun::Wake(t0, 100), false}}, /*active_high=*/false);
  ASSERT_EQ(run.loop->Run(false, 1000), RunEnd::kEnded);
  auto rows = run.loop->rows();
  EXPECT_GT(Norm(rows[99].force_n), 0.5);
  EXPECT_EQ(Norm(rows[100].force_n), 0.0);
  EXPECT_EQ(run.loop->counters().estop_ticks, 300u);

  EstopRun failing(field, {});
  failing.input.set_fail(true);  // an unreadable e-stop is an asserted e-stop
  ASSERT_EQ(failing.loop->Run(false, 1000), RunEnd::kEnded);
  EXPECT_EQ(failing.loop->counters().estop_ticks, 400u);
  EXPECT_EQ(failing.loop->counters().gpio_errors, 401u) << "400 ticks and the read that found the replay's end";
  EXPECT_EQ(failing.loop->counters().max_force_n, 0.0);
}

// ---------------------------------------------------------------- tick line

TEST(RuntimeLoop, TickLineTogglesOncePerTickAtTheWakeUpAndShowsAStall) {
  const SphereField field;
  FakeClock clock;
  const std::int64_t t0 = clock.now_ns;
  std::vector<std::int64_t> cost(50, 20'000);
  cost[20] = 3'500'000;  // tick 20 stalls 3.5 periods in the device
  TickDevice device(clock, FreeHips(field, 50), cost);
  gpio_sim::SimOutput line(clock, 100);
  std::atomic<bool> stop{false};
  ServoConfig c;
  c.clock = &clock;
  c.tick_line = &line;
  ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);
  ASSERT_EQ(loop.Run(false, 1000), RunEnd::kEnded);
  const auto log = line.log();
  ASSERT_EQ(log.size(), 51u) << "50 ticks and the attempt that found the replay's end";
  for (std::size_t n = 0; n < log.size(); ++n) {
    EXPECT_EQ(log[n].level, n % 2 == 0) << "alternating, first edge rising";
    if (n <= 20) {
      EXPECT_EQ(log[n].t_ns, t0 + static_cast<std::int64_t>(n + 1) * kPeriod) << n;
    }
  }
  // On a scope: one period between edges, except the 4-period gap the stall leaves.
  EXPECT_EQ(log[21].t_ns - log[20].t_ns, 4 * kPeriod);
  EXPECT_EQ(log[22].t_ns - log[21].t_ns, kPeriod);
}

// ---------------------------------------------------------------- watchdog (wall-clock time)

// Blocks in Read at tick `stall_at` for `stall_ms`, then returns `after` (kError: the device
// layer's own timeout fired; kOk: the transfer finally completed). Records the writes.
class StallingDevice final : public device::HapticDevice {
 public:
  StallingDevice(const SphereField& field, int stall_at, int stall_ms, device::IoStatus after)
      : inside_(field.PointAt(field.radius_m() - 1e-3, {1, 0, 0})),
        outside_(field.PointAt(field.radius_m() + 1e-3, {1, 0, 0})),
        stall_at_(stall_at),
        stall_ms_(stall_ms),
        after_(after) {
    writes.reserve(10000);
  }
  std::vector<std::array<double, 3>> writes;
  std::atomic<int> reads{0};

 private:
  device::IoStatus DoRead(device::HipReading& out) override {
    const int n = reads.fetch_add(1);
    const double u = std::min(1.0, n / 10.0);
    for (std::size_t a = 0; a < 3; ++a) out.hip_m[a] = outside_[a] + (inside_[a] - outside_[a]) * u;
    if (n == stall_at_) {
      std::this_thread::sleep_for(std::chrono::milliseconds(stall_ms_));
      return after_;
    }
    return n >= 400 ? device::IoStatus::kEnd : device::IoStatus::kOk;
  }
  device::IoStatus DoWrite(const std::array<double, 3>& f) override {
    writes.push_back(f);
    return device::IoStatus::kOk;
  }
  std::array<double, 3> inside_, outside_;
  int stall_at_, stall_ms_;
  device::IoStatus after_;
};

struct TripLog {
  std::atomic<int> trips{0};
  std::atomic<std::int64_t> stalled_ns{0};
};
void RecordTrip(void* ctx, std::int64_t stalled_ns) {
  auto* t = static_cast<TripLog*>(ctx);
  t->stalled_ns.store(stalled_ns);
  t->trips.fetch_add(1);
}

TEST(RuntimeWatchdog, AStallWithoutADeviceTimeoutTripsAndTheLoopWritesZeroWhenTheCallReturns) {
  const SphereField field;
  StallingDevice device(field, 50, 400, device::IoStatus::kOk);  // the transfer returns after 0.4 s
  std::atomic<bool> stop{false};
  ServoLoop loop(field.view(), Params(field.voxel_m()), device, 1000, stop);
  TripLog log;
  Watchdog dog(loop, {100'000'000, &RecordTrip, &log});  // 100 ms: no false trip on a loaded test box
  ASSERT_EQ(dog.Start(), 0);
  const RunEnd end = loop.Run(false, 1000);
  dog.Stop();
  EXPECT_EQ(end, RunEnd::kWatchdogFault);
  EXPECT_EQ(dog.trips(), 1u);
  EXPECT_EQ(log.trips.load(), 1);
  EXPECT_GE(log.stalled_ns.load(), 100'000'000);
  EXPECT_LT(log.stalled_ns.load(), 400'000'000) << "tripped during the stall, not after";
  EXPECT_EQ(loop.fault(), FaultCause::kWatchdog);
  EXPECT_EQ(loop.counters().ticks, 50u) << "the stalled tick computed no force";
  ASSERT_GE(device.writes.size(), 51u);
  EXPECT_GT(Norm(device.writes[49]), 0.5) << "in contact before the stall";
  for (std::size_t i = 50; i < device.writes.size(); ++i)
    EXPECT_EQ(device.writes[i], (std::array<double, 3>{0, 0, 0})) << "every write after the stall is zero";
}

TEST(RuntimeWatchdog, ADeviceTimeoutZeroesTheForceInThatTickAndTheTickLineShowsTheGap) {
  const SphereField field;
  StallingDevice device(field, 50, 30, device::IoStatus::kError);  // its own 30 ms timeout fires
  std::atomic<bool> stop{false};
  gpio_sim::SimOutput line(rt::MonotonicClock(), 1000);
  ServoConfig c;
  c.telemetry_capacity = 1000;
  c.tick_line = &line;
  c.overrun_fault_limit = 0;
  ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);
  TripLog log;
  Watchdog dog(loop, {200'000'000, &RecordTrip, &log});  // 200 ms: longer than the device's timeout
  ASSERT_EQ(dog.Start(), 0);
  const RunEnd end = loop.Run(false, 1000);
  dog.Stop();
  EXPECT_EQ(end, RunEnd::kDeviceError);
  EXPECT_EQ(dog.trips(), 0u) << "the device's own timeout came first";
  EXPECT_EQ(loop.counters().device_errors, 1u);
  EXPECT_GT(Norm(device.writes[49]), 0.5);
  EXPECT_EQ(device.writes.at(50), (std::array<double, 3>{0, 0, 0})) << "zero in the tick that timed out";
  // The tick line toggled at the start of tick 50 and never again: an external watchdog watching
  // it sees the line stop for the whole stall.
  const auto edges = line.log();
  ASSERT_EQ(edges.size(), 51u);
  EXPECT_GE(rt::MonotonicClock().NowNs() - edges.back().t_ns, 30'000'000);
}

// ---------------------------------------------------------------- telemetry drain

TEST(TelemetryDrain, StreamedCsvEqualsTheWholeLogAndNothingIsDroppedInLockstep) {
  const SphereField field;
  const std::string dir = ::testing::TempDir();
  const std::string streamed = dir + "/palpa_drain_streamed.csv", whole = dir + "/palpa_drain_whole.csv";
  const std::string status = dir + "/palpa_drain_status.json";
  // Reference: a big undrained ring, written at the end.
  {
    std::atomic<bool> stop{false};
    device_sim::SimDevice device(firmware_test::PressSlideLeaveTrace(field), 1000.0);
    ServoLoop loop(field.view(), Params(field.voxel_m()), device, device.TickCount(), stop);
    ASSERT_EQ(loop.Run(true, 1000), RunEnd::kEnded);
    ASSERT_TRUE(WriteCsvAtomic(whole, loop.rows()).has_value());
  }
  // Streamed: a 64-sample ring drained while the loop runs, the loop waiting for room (lockstep).
  std::atomic<bool> stop{false};
  device_sim::SimDevice device(firmware_test::PressSlideLeaveTrace(field), 1000.0);
  ServoConfig c;
  c.telemetry_capacity = 64;
  c.wait_when_full = true;
  ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);
  auto file = io::AtomicFile::Create(streamed);
  ASSERT_TRUE(file.has_value());
  DrainConfig dc;
  dc.csv = file->file();
  dc.status_path = status;
  dc.fast = true;
  dc.rate_hz = 1000;
  TelemetryDrain drain(loop.telemetry(), dc);
  ASSERT_EQ(drain.Start(), 0);
  ASSERT_EQ(loop.Run(true, 1000), RunEnd::kEnded);
  drain.Stop("ended");
  ASSERT_FALSE(drain.csv_failed());
  ASSERT_TRUE(file->Commit().has_value());
  EXPECT_EQ(loop.counters().dropped_rows, 0u);
  EXPECT_EQ(drain.rows_written(), 10001u);
  const std::string a = ReadAll(streamed), b = ReadAll(whole);
  EXPECT_GT(a.size(), 10001u * 20);
  EXPECT_EQ(a, b);
  const std::string st = ReadAll(status);
  for (const char* key :
       {"\"state\": \"ended\"", "\"samples\": 10001", "\"dropped\": 0", "\"realtime\": false", "\"last_tick\": 10000"})
    EXPECT_NE(st.find(key), std::string::npos) << key << " in " << st;
  EXPECT_EQ(drain.status().contact_ticks, loop.counters().contact_ticks);
  std::remove(streamed.c_str());
  std::remove(whole.c_str());
  std::remove(status.c_str());
}

TEST(TelemetryDrain, APacedLoopNeverWaitsForTheDrainItDropsAndCounts) {
  const SphereField field;
  FakeClock clock;
  TickDevice device(clock, FreeHips(field, 500));
  std::atomic<bool> stop{false};
  ServoConfig c;
  c.clock = &clock;
  c.telemetry_capacity = 100;  // nobody drains: 400 of 500 must be dropped, none waited for
  ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);
  ASSERT_EQ(loop.Run(false, 1000), RunEnd::kEnded);
  EXPECT_EQ(loop.counters().ticks, 500u);
  EXPECT_EQ(loop.counters().dropped_rows, 400u);
  EXPECT_EQ(loop.telemetry().dropped(), 400u);
  const auto rows = loop.rows();
  ASSERT_EQ(rows.size(), 100u);
  EXPECT_DOUBLE_EQ(rows.front().t_s, 0.0) << "the first 100 are kept (drop-newest)";
  EXPECT_DOUBLE_EQ(rows.back().t_s, 0.099);
}

}  // namespace
}  // namespace palpa::servo
