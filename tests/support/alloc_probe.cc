#include "alloc_probe.h"

#include <pthread.h>
#include <sched.h>
#include <time.h>
#include <unistd.h>

#include <cstddef>
#include <cstdlib>
#include <mutex>
#include <new>
#include <vector>

#include <gtest/gtest.h>

namespace palpa::alloc_probe {

thread_local bool g_armed = false;
std::atomic<long> g_allocs{0};
std::atomic<long> g_frees{0};
std::atomic<long> g_locks{0};
std::atomic<long> g_syscalls{0};

void ResetCounters() {
  g_allocs = 0;
  g_frees = 0;
  g_locks = 0;
  g_syscalls = 0;
}

void ExpectSeesMallocAndNew() {
  ResetCounters();
  {
    const Armed armed;
    void* volatile p = std::malloc(32);  // volatile: the compiler may not elide the pair
    std::free(p);
    int* volatile q = new int(7);
    delete q;
  }
  EXPECT_GE(g_allocs.load(), 2);
  EXPECT_GE(g_frees.load(), 2);
}

void ExpectSeesVectorGrowthInsideLibstdcxx() {
  ResetCounters();
  {
    const Armed armed;
    std::vector<int> v;
    v.push_back(1);  // operator new called from the std::vector code
    v.push_back(2);
  }
  EXPECT_GE(g_allocs.load(), 2);
}

void ExpectSeesMutexLock() {
  ResetCounters();
  std::mutex m;
  {
    const Armed armed;
    const std::lock_guard<std::mutex> lock(m);
  }
  EXPECT_GE(g_locks.load(), 1);
}

void ExpectSeesSleepAndWrite() {
  ResetCounters();
  {
    const Armed armed;
    timespec ts{0, 1};
    nanosleep(&ts, nullptr);
    (void)!write(-1, "", 0);
  }
  EXPECT_EQ(g_syscalls.load(), 2);
}

void ExpectIgnoresCallsWhenDisarmed() {
  ResetCounters();
  void* volatile p = std::malloc(32);
  std::free(p);
  EXPECT_EQ(g_allocs.load(), 0);
}

}  // namespace palpa::alloc_probe

namespace {

using palpa::alloc_probe::g_armed;

void Count(std::atomic<long>& counter) {
  if (g_armed) counter.fetch_add(1, std::memory_order_relaxed);
}
void CountAlloc() { Count(palpa::alloc_probe::g_allocs); }
void CountFree() { Count(palpa::alloc_probe::g_frees); }
void CountSyscall() { Count(palpa::alloc_probe::g_syscalls); }

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

// ---- link-time wraps (-Wl,--wrap=NAME routes the test's objects' NAME to __wrap_NAME) ----
extern "C" {
void* __real_malloc(std::size_t n);
void* __real_calloc(std::size_t n, std::size_t size);
void* __real_realloc(void* p, std::size_t n);
void __real_free(void* p);
void* __real_aligned_alloc(std::size_t al, std::size_t n);
int __real_posix_memalign(void** out, std::size_t al, std::size_t n);
int __real_pthread_mutex_lock(pthread_mutex_t* m);
int __real_clock_nanosleep(clockid_t c, int flags, const timespec* t, timespec* rem);
int __real_nanosleep(const timespec* t, timespec* rem);
int __real_usleep(useconds_t us);
int __real_sched_yield();
ssize_t __real_write(int fd, const void* buf, std::size_t n);
ssize_t __real_read(int fd, void* buf, std::size_t n);

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
  Count(palpa::alloc_probe::g_locks);
  return __real_pthread_mutex_lock(m);
}
int __wrap_clock_nanosleep(clockid_t c, int flags, const timespec* t, timespec* rem) {
  CountSyscall();
  return __real_clock_nanosleep(c, flags, t, rem);
}
int __wrap_nanosleep(const timespec* t, timespec* rem) {
  CountSyscall();
  return __real_nanosleep(t, rem);
}
int __wrap_usleep(useconds_t us) {
  CountSyscall();
  return __real_usleep(us);
}
int __wrap_sched_yield() {
  CountSyscall();
  return __real_sched_yield();
}
ssize_t __wrap_write(int fd, const void* buf, std::size_t n) {
  CountSyscall();
  return __real_write(fd, buf, n);
}
ssize_t __wrap_read(int fd, void* buf, std::size_t n) {
  CountSyscall();
  return __real_read(fd, buf, n);
}
}
