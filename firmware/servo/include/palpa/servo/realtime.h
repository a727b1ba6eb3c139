// Turning the calling thread into the servo thread (house style §2), once, before Run(). Non-RT.
#pragma once

#include <cstddef>
#include <string>

namespace palpa::servo {

/// Stack the servo thread may use without page faults after PrepareRealtimeThread.
inline constexpr std::size_t kPrefaultStackBytes = 64 * 1024;

/// What PrepareRealtimeThread managed. `problems` lists each failed step, one sentence per line
/// (empty when all succeeded); the caller warns with it and treats the run as "not RT".
struct RealtimeReport {
  bool memory_locked = false;  ///< mlockall(MCL_CURRENT) succeeded
  bool fifo = false;           ///< SCHED_FIFO at the requested priority
  std::string problems;
  bool ok() const { return problems.empty(); }
};

/// In order: pre-fault kPrefaultStackBytes of stack; mlockall(MCL_CURRENT) — call it after the
/// log is allocated; MCL_FUTURE is not used so that allocation after the run cannot fail against
/// RLIMIT_MEMLOCK; SCHED_FIFO at `fifo_priority` (1..99); thread name "palpad-servo". Each step is
/// tried even if an earlier one failed. Non-RT; affects the calling thread (memory lock: process).
RealtimeReport PrepareRealtimeThread(int fifo_priority);

}  // namespace palpa::servo
