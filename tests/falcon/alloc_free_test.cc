// Proves the Falcon servo tick (FalconDevice: codec, re-framing, encoder checks, forward
// kinematics, force → counts; the virtual Falcon's transfers and mechanics) allocation- and
// lock-free, including the fault ticks. Same interposer as tests/firmware/alloc_free_test.cc:
// global operator new/delete replaced, malloc & co. and pthread_mutex_lock wrapped at link time;
// the last tests prove the counters see a call.

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

#include "palpa/device_falcon/falcon_device.h"
#include "palpa/device_virtual_falcon/virtual_falcon.h"
#include "palpa/proxy/proxy.h"
#include "palpa/servo/servo_loop.h"
#include "sphere_fixture.h"

namespace {

thread_local bool g_armed = false;
std::atomic<long> g_allocs{0};
std::atomic<long> g_frees{0};
std::atomic<long> g_locks{0};

void CountAlloc() {
  if (g_armed) g_allocs.fetch_add(1, std::memory_order_relaxed);
}
void CountFree() {
  if (g_armed) g_frees.fetch_add(1, std::memory_order_relaxed);
}

void* AllocOrThrow(std::size_t n) {
  CountAlloc();
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void* AllocAligned(std::size_t n, std::align_val_t al) {
  CountAlloc();
  const auto a = static_cast<std::size_t>(al);
  const std::size_t size = ((n == 0 ? 1 : n) + a - 1) / a * a;  // aligned_alloc wants a multiple
  return std::aligned_alloc(a, size);
}
void* AllocAlignedOrThrow(std::size_t n, std::align_val_t al) {
  if (void* p = AllocAligned(n, al)) return p;
  throw std::bad_alloc();
}
void Release(void* p) {
  CountFree();
  std::free(p);
}

// RAII arming of the counters on this thread.
class Armed {
 public:
  Armed() { g_armed = true; }
  ~Armed() { g_armed = false; }
  Armed(const Armed&) = delete;
  Armed& operator=(const Armed&) = delete;
};

void ResetCounters() {
  g_allocs = 0;
  g_frees = 0;
  g_locks = 0;
}

}  // namespace

// ---- replaced global allocation functions (all forms) ----
void* operator new(std::size_t n) { return AllocOrThrow(n); }
void* operator new[](std::size_t n) { return AllocOrThrow(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  CountAlloc();
  return std::malloc(n == 0 ? 1 : n);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  CountAlloc();
  return std::malloc(n == 0 ? 1 : n);
}
void* operator new(std::size_t n, std::align_val_t al) { return AllocAlignedOrThrow(n, al); }
void* operator new[](std::size_t n, std::align_val_t al) { return AllocAlignedOrThrow(n, al); }
void* operator new(std::size_t n, std::align_val_t al, const std::nothrow_t&) noexcept { return AllocAligned(n, al); }
void* operator new[](std::size_t n, std::align_val_t al, const std::nothrow_t&) noexcept { return AllocAligned(n, al); }
void operator delete(void* p) noexcept { Release(p); }
void operator delete[](void* p) noexcept { Release(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { Release(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { Release(p); }
void operator delete(void* p, std::size_t) noexcept { Release(p); }
void operator delete[](void* p, std::size_t) noexcept { Release(p); }
void operator delete(void* p, std::align_val_t) noexcept { Release(p); }
void operator delete[](void* p, std::align_val_t) noexcept { Release(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { Release(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { Release(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { Release(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { Release(p); }

// ---- link-time wraps (-Wl,--wrap=NAME routes our objects' NAME to __wrap_NAME) ----
extern "C" {
void* __real_malloc(std::size_t n);
void* __real_calloc(std::size_t n, std::size_t size);
void* __real_realloc(void* p, std::size_t n);
void __real_free(void* p);
void* __real_aligned_alloc(std::size_t al, std::size_t n);
int __real_posix_memalign(void** out, std::size_t al, std::size_t n);
int __real_pthread_mutex_lock(pthread_mutex_t* m);

void* __wrap_malloc(std::size_t n) {
  CountAlloc();
  return __real_malloc(n);
}
void* __wrap_calloc(std::size_t n, std::size_t size) {
  CountAlloc();
  return __real_calloc(n, size);
}
void* __wrap_realloc(void* p, std::size_t n) {
  CountAlloc();
  return __real_realloc(p, n);
}
void __wrap_free(void* p) {
  CountFree();
  __real_free(p);
}
void* __wrap_aligned_alloc(std::size_t al, std::size_t n) {
  CountAlloc();
  return __real_aligned_alloc(al, n);
}
int __wrap_posix_memalign(void** out, std::size_t al, std::size_t n) {
  CountAlloc();
  return __real_posix_memalign(out, al, n);
}
int __wrap_pthread_mutex_lock(pthread_mutex_t* m) {
  if (g_armed) g_locks.fetch_add(1, std::memory_order_relaxed);
  return __real_pthread_mutex_lock(m);
}
}

namespace palpa {
namespace {

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

TEST(FalconAllocFree, CounterSeesMallocAndNew) {
  ResetCounters();
  {
    const Armed armed;
    void* volatile p = std::malloc(32);
    std::free(p);
    int* volatile q = new int(7);
    delete q;
  }
  EXPECT_GE(g_allocs.load(), 2);
  EXPECT_GE(g_frees.load(), 2);
}

TEST(FalconAllocFree, CounterSeesMutexLock) {
  ResetCounters();
  std::mutex m;
  {
    const Armed armed;
    const std::lock_guard<std::mutex> lock(m);
  }
  EXPECT_GE(g_locks.load(), 1);
}

}  // namespace
}  // namespace palpa
