// The allocation, lock and system-call probe of the real-time tests (docs/realtime-core.md,
// "Allocation-free tick"): linking alloc_probe.cc replaces global operator new/delete (every
// form) and, through `palpa_use_alloc_probe(target)` (tests/support/CMakeLists.txt), wraps
// malloc & co., pthread_mutex_lock and the system calls a loop could slip in (sleeps, read, write,
// sched_yield) at link time (-Wl,--wrap). While the calling thread is armed, each call is counted.
// Every test that uses it keeps a must-fail sibling that proves the counters see a call.
#pragma once

#include <atomic>

namespace palpa::alloc_probe {

extern thread_local bool g_armed;     ///< counting on this thread
extern std::atomic<long> g_allocs;    ///< new, new[], malloc, calloc, realloc, aligned_alloc, posix_memalign
extern std::atomic<long> g_frees;     ///< delete, delete[], free
extern std::atomic<long> g_locks;     ///< pthread_mutex_lock (std::mutex::lock too)
extern std::atomic<long> g_syscalls;  ///< clock_nanosleep, nanosleep, usleep, sched_yield, read, write

/// Zeroes every counter (non-RT; call before arming).
void ResetCounters();

/// RAII arming of the counters on this thread.
class Armed {
 public:
  Armed() { g_armed = true; }
  ~Armed() { g_armed = false; }
  Armed(const Armed&) = delete;
  Armed& operator=(const Armed&) = delete;
};

// The detector checks each executable that links the probe runs (without them, a 0 proves
// nothing): armed, a malloc/free and a new/delete pair, std::vector growth inside libstdc++, a
// std::mutex lock, a nanosleep and a write are each counted; disarmed, nothing is.
void ExpectSeesMallocAndNew();
void ExpectSeesVectorGrowthInsideLibstdcxx();
void ExpectSeesMutexLock();
void ExpectSeesSleepAndWrite();
void ExpectIgnoresCallsWhenDisarmed();

}  // namespace palpa::alloc_probe
