// Proves the Falcon servo tick (FalconDevice: codec, re-framing, encoder checks, forward
// kinematics, force → counts; the virtual Falcon's transfers and mechanics) allocation- and
// lock-free, including the fault ticks, with the probe of tests/support/alloc_probe.h (global
// operator new/delete replaced, malloc & co. and pthread_mutex_lock wrapped at link time); the
// last tests prove the counters see a call.

#include <gtest/gtest.h>
#include <pthread.h>

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <mutex>
#include <new>
#include <vector>

#include "alloc_probe.h"
#include "palpa/device_falcon/falcon_device.h"
#include "palpa/device_virtual_falcon/virtual_falcon.h"
#include "palpa/proxy/proxy.h"
#include "palpa/servo/servo_loop.h"
#include "sphere_fixture.h"

namespace palpa {
namespace {

using alloc_probe::Armed;
using alloc_probe::g_allocs;
using alloc_probe::g_frees;
using alloc_probe::g_locks;
using alloc_probe::ResetCounters;

using device_virtual_falcon::FaultKind;
using device_virtual_falcon::FaultSpec;
using firmware_test::SphereField;

// Bring-up (non-RT) outside the armed region, then `ticks` servo steps armed.
struct Outcome {
  servo::StepResult last = servo::StepResult::kRunning;
  std::uint64_t ticks = 0, contact = 0;
};

Outcome RunArmed(std::vector<FaultSpec> faults, int ticks) {
  const SphereField field;
  const double r = field.radius_m();
  device_virtual_falcon::VirtualFalconConfig c;
  c.trace = firmware_test::TraceFromKeys(
      field, {{0.0, r + 3e-3, {0, 0.3, 1}}, {0.3, r - 2e-3, {0, 0.3, 1}}, {2.0, r - 2e-3, {0.4, 0.3, 1}}}, 0.01);
  c.faults = std::move(faults);
  device_virtual_falcon::VirtualFalcon falcon(std::move(c));
  device_falcon::FalconDevice device(falcon);
  std::string log;
  EXPECT_EQ(device.Configure(nullptr, device_falcon::LoaderConfig{}, log), device_falcon::ConfigureResult::kOk);
  std::atomic<bool> stop{false};
  EXPECT_EQ(device.Home(stop, 10.0), device_falcon::HomeResult::kHomed);
  EXPECT_TRUE(device.Activate());
  auto params = proxy::MakeProxyParams(proxy::ProxyConfig{}, field.voxel_m());
  servo::ServoLoop loop(field.view(), *params, device, static_cast<std::size_t>(ticks), stop);
  Outcome o;
  ResetCounters();
  {
    const Armed armed;
    for (int i = 0; i < ticks && o.last == servo::StepResult::kRunning; ++i) o.last = loop.Step();
  }
  o.ticks = loop.counters().ticks;
  o.contact = loop.counters().contact_ticks;
  return o;
}

TEST(FalconAllocFree, ServoTicksOnTheVirtualFalconAllocateNothing) {
  const Outcome o = RunArmed({{FaultKind::kSplit, 0}, {FaultKind::kGarbage, 200}}, 1500);
  EXPECT_EQ(o.last, servo::StepResult::kRunning);
  EXPECT_EQ(o.ticks, 1500u);
  EXPECT_GT(o.contact, 500u);
  EXPECT_EQ(g_allocs.load(), 0);
  EXPECT_EQ(g_frees.load(), 0);
  EXPECT_EQ(g_locks.load(), 0);
}

TEST(FalconAllocFree, FaultTicksAllocateNothing) {
  for (const FaultKind k : {FaultKind::kDrop, FaultKind::kUnplug, FaultKind::kJump, FaultKind::kCorrupt}) {
    const Outcome o = RunArmed({{k, 700}}, 1500);
    EXPECT_EQ(o.last, servo::StepResult::kDeviceError);
    EXPECT_EQ(g_allocs.load(), 0);
    EXPECT_EQ(g_frees.load(), 0);
    EXPECT_EQ(g_locks.load(), 0);
  }
}

// The detector itself: without these passing, a 0 above proves nothing.
TEST(FalconAllocFree, CounterSeesMallocAndNew) { alloc_probe::ExpectSeesMallocAndNew(); }
TEST(FalconAllocFree, CounterSeesMutexLock) { alloc_probe::ExpectSeesMutexLock(); }

}  // namespace
}  // namespace palpa
