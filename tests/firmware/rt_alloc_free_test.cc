// Proves the runtime paths of the servo tick allocation-, lock- and system-call-free: e-stop
// assertion, debounced release and force ramp, the tick line, telemetry pushes into a full ring
// (drops), consecutive overruns into the fault state, and a fault requested by the watchdog.
// The probe of tests/support/alloc_probe.h replaces global operator new/delete and wraps malloc &
// co., pthread_mutex_lock and the system calls a loop could slip in (sleeps, read/write,
// sched_yield) at link time; while armed, each call is counted. On the
// simulated clock the loop needs no system call at all, so any call is a finding. The detector
// tests at the end prove that the counters see a call. (The base tick's test is alloc_free_test.cc.)

#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cstdarg>
#include <cstdlib>
#include <new>

#include "alloc_probe.h"
#include "palpa/gpio_sim/sim_gpio.h"
#include "palpa/proxy/proxy.h"
#include "palpa/servo/servo_loop.h"
#include "runtime_fixtures.h"
#include "sphere_fixture.h"

namespace palpa {
namespace {

using alloc_probe::Armed;
using alloc_probe::g_allocs;
using alloc_probe::g_locks;
using alloc_probe::g_syscalls;
using alloc_probe::ResetCounters;

using firmware_test::FakeClock;
using firmware_test::SphereField;
using firmware_test::TickDevice;

constexpr std::int64_t kPeriod = 1'000'000;

proxy::ProxyParams Params(double voxel_m) {
  auto p = proxy::MakeProxyParams(proxy::ProxyConfig{}, voxel_m);
  if (!p) {  // without parameters nothing below is meaningful: stop rather than read an empty expected
    ADD_FAILURE() << "MakeProxyParams: " << p.error();
    std::abort();
  }
  return *p;
}

// 1 mm outside → 1 mm inside over ticks 0..9, held; out at 150..159; in again at 240..249.
std::vector<std::array<double, 3>> Scenario(const SphereField& field, std::size_t n) {
  std::vector<std::array<double, 3>> hips(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double t = static_cast<double>(i);
    double depth = std::min(1e-3, -1e-3 + 2e-3 * t / 9.0);
    if (i >= 150) depth = std::max(-2e-3, 1e-3 - 3e-3 * (t - 150) / 9.0);
    if (i >= 240) depth = std::min(1e-3, -2e-3 + 3e-3 * (t - 240) / 9.0);
    hips[i] = field.PointAt(field.radius_m() - depth, {0, 1, 0});
  }
  return hips;
}

TEST(RtAllocFree, EstopRampTickLineDropsAndOverrunFaultTouchNoAllocatorLockOrSyscall) {
  const SphereField field;
  FakeClock clock;
  const std::int64_t t0 = clock.now_ns;
  const auto wake = [&](std::int64_t n) { return t0 + (n + 1) * kPeriod; };
  gpio_sim::SimInput estop(clock, {{wake(100), true}, {wake(180), false}, {wake(182), true}, {wake(200), false}});
  gpio_sim::SimOutput tick_line(clock, 1000);
  std::vector<std::int64_t> cost(600, 20'000);
  for (std::size_t i = 500; i < 600; ++i) cost[i] = 1'300'000;  // from tick 500: overruns → fault
  TickDevice device(clock, Scenario(field, 600), cost);
  std::atomic<bool> stop{false};
  servo::ServoConfig c;
  c.clock = &clock;
  c.telemetry_capacity = 128;  // undrained: most samples are dropped, on the RT path
  c.overrun_fault_limit = 5;
  c.estop = &estop;
  c.estop_release_ticks = 5;
  c.ramp_ticks = 50;
  c.tick_line = &tick_line;
  servo::ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);

  ResetCounters();
  servo::RunEnd end{};
  {
    const Armed armed;
    end = loop.Run(/*fast=*/false, 1000.0);
  }
  EXPECT_EQ(g_allocs.load(), 0);
  EXPECT_EQ(g_locks.load(), 0);
  EXPECT_EQ(g_syscalls.load(), 0);
  // The paths under test were taken.
  EXPECT_EQ(end, servo::RunEnd::kOverrunFault);
  EXPECT_EQ(loop.counters().estop_events, 1u);
  EXPECT_EQ(loop.counters().estop_ticks, 104u);
  EXPECT_GT(loop.counters().contact_ticks, 200u);
  EXPECT_EQ(loop.counters().ticks, 505u);
  EXPECT_EQ(loop.counters().dropped_rows, 505u - 128u);
  EXPECT_EQ(tick_line.sets(), 505u);
}

TEST(RtAllocFree, WatchdogFaultPathTouchesNothing) {
  const SphereField field;
  FakeClock clock;
  TickDevice device(clock, Scenario(field, 100));
  std::atomic<bool> stop{false};
  servo::ServoConfig c;
  c.clock = &clock;
  servo::ServoLoop loop(field.view(), Params(field.voxel_m()), device, c, stop);
  ResetCounters();
  servo::StepResult first{}, faulted{};
  {
    const Armed armed;
    for (int i = 0; i < 20; ++i) first = loop.Step();
    loop.RequestFault(servo::FaultCause::kWatchdog);  // what the watchdog thread does
    faulted = loop.Step();
  }
  EXPECT_EQ(g_allocs.load(), 0);
  EXPECT_EQ(g_locks.load(), 0);
  EXPECT_EQ(g_syscalls.load(), 0);
  EXPECT_EQ(first, servo::StepResult::kRunning);
  EXPECT_EQ(faulted, servo::StepResult::kFault);
  EXPECT_EQ(device.writes().back(), (std::array<double, 3>{0, 0, 0}));
}

// The detector itself.
TEST(RtAllocFree, DetectorSeesASleepAWriteAndAnAllocation) {
  alloc_probe::ExpectSeesSleepAndWrite();
  alloc_probe::ExpectSeesMallocAndNew();
}

}  // namespace
}  // namespace palpa
