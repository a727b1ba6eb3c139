// Helper threads next to the servo thread (telemetry drain, watchdog): ordinary SCHED_OTHER
// threads with small stacks. Explicit scheduling, so a helper started by an already SCHED_FIFO
// thread does not inherit FIFO; small stacks, so mlockall(MCL_CURRENT | MCL_FUTURE) locks 256 KiB
// per helper rather than glibc's default 8 MiB (which would exceed an unprivileged
// RLIMIT_MEMLOCK). Non-RT.
#pragma once

#include <pthread.h>

#include <cstddef>

namespace palpa::rt {

class HelperThread {
 public:
  HelperThread() = default;
  HelperThread(const HelperThread&) = delete;
  HelperThread& operator=(const HelperThread&) = delete;
  /// Joins if still running.
  ~HelperThread();

  /// Starts `body(arg)` on a new thread named `name` (≤ 15 bytes). With `avoid_cpu` ≥ 0 the
  /// thread may run on every CPU this process may use except that one (the servo thread's, so a
  /// helper never competes with it there); if that leaves no CPU, on any. Returns 0 or an errno.
  int Start(const char* name, void (*body)(void*), void* arg, int avoid_cpu = -1, std::size_t stack_bytes = 256 * 1024);
  /// Waits for the body to return. Idempotent.
  void Join();
  bool running() const { return started_; }

 private:
  static void* Trampoline(void* self);

  pthread_t thread_{};
  bool started_ = false;
  void (*body_)(void*) = nullptr;
  void* arg_ = nullptr;
};

}  // namespace palpa::rt
