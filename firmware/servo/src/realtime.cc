#include "palpa/servo/realtime.h"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstddef>
#include <cstring>

namespace palpa::servo {
namespace {

// Touches kPrefaultStackBytes of stack below the caller so the loop's first deep call does not
// page-fault. noinline + volatile keep the array from being optimised away.
[[gnu::noinline]] void PrefaultStack() {
  volatile unsigned char stack[kPrefaultStackBytes];
  for (std::size_t i = 0; i < kPrefaultStackBytes; i += 4096) stack[i] = 0;
  [[maybe_unused]] const unsigned char last = stack[kPrefaultStackBytes - 1];  // a volatile read: "used"
}

void Note(std::string& problems, const char* step, int err) {
  problems += step;
  problems += ": ";
  problems += std::strerror(err);
  problems += '\n';
}

}  // namespace

RealtimeReport PrepareRealtimeThread(int fifo_priority) {
  RealtimeReport report;
  PrefaultStack();  // first, so that mlockall(MCL_CURRENT) locks the grown stack too
  if (mlockall(MCL_CURRENT) == 0) {
    report.memory_locked = true;
  } else {
    Note(report.problems, "mlockall(MCL_CURRENT) failed", errno);
  }
  sched_param param{};
  param.sched_priority = fifo_priority;
  if (const int err = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param); err == 0) {
    report.fifo = true;
  } else {
    Note(report.problems, "SCHED_FIFO failed", err);
  }
  (void)pthread_setname_np(pthread_self(), "palpad-servo");  // cosmetic (top, perf); ignore failure
  return report;
}

}  // namespace palpa::servo
