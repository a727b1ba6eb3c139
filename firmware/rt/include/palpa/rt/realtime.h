// Turning the calling thread into the servo thread, once, at start-up (house style §2). Non-RT.
//
// Steps, in order: lock memory (mlockall(MCL_CURRENT | MCL_FUTURE)); pre-fault the stack and every
// buffer the loop touches; pin the thread to one CPU; SCHED_FIFO at the requested priority; hold
// /dev/cpu_dma_latency at 0 µs (no deep C-state exits, as cyclictest does); name the thread. Each
// step is tried even if an earlier one failed. A step the system refuses is recorded with its
// errno; the caller prints Warnings() — one loud line per refused step — and marks the run
// "not real-time" in its summary, status and reports (realtime() is false). Never silent.
//
// Every system call goes through RtSyscalls, so tests can provoke each refusal without needing
// to be unprivileged (tests/firmware/rt_test.cc).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace palpa::rt {

/// Stack the servo thread may use without a page fault after the set-up.
inline constexpr std::size_t kPrefaultStackBytes = 64 * 1024;

enum class RtStep : std::uint8_t { kMemoryLock, kPrefault, kAffinity, kFifo, kPmQos, kThreadName };
inline constexpr std::size_t kRtStepCount = 6;
/// "memory lock", "pre-fault", "CPU affinity", "SCHED_FIFO", "cpu_dma_latency", "thread name".
const char* RtStepName(RtStep step);

/// The system calls behind the steps. Each returns 0 on success or a positive errno value;
/// open_pm_qos returns a file descriptor ≥ 0 or a negative errno value.
struct RtSyscalls {
  int (*lock_memory)();                      ///< mlockall(MCL_CURRENT | MCL_FUTURE)
  int (*set_affinity)(int cpu);              ///< calling thread on `cpu` only
  int (*set_fifo)(int priority);             ///< calling thread SCHED_FIFO at `priority`
  int (*open_pm_qos)(std::int32_t max_us);   ///< open /dev/cpu_dma_latency and write max_us
  void (*close_pm_qos)(int fd);              ///< releases the request
  int (*set_thread_name)(const char* name);  ///< pthread_setname_np(pthread_self(), name)
};

/// The real Linux calls.
const RtSyscalls& LinuxRtSyscalls();

/// What to set up. The defaults are palpad's.
struct RtRequest {
  int cpu = -1;                              ///< pin to this CPU (0-based); −1: leave unpinned (not a refusal)
  int priority = 80;                         ///< SCHED_FIFO priority, 1..99
  bool pm_qos = true;                        ///< hold /dev/cpu_dma_latency at 0 µs while the set-up lives
  const char* thread_name = "palpad-servo";  ///< ≤ 15 bytes (the kernel's limit)
  /// Buffers the loop reads or writes after start. Each was written once when allocated
  /// (value-initialised); the pre-fault reads one byte per page so that the pages are resident
  /// before the first tick, also when the memory lock was refused.
  std::span<const std::span<const std::byte>> buffers;
};

/// Outcome of one step.
struct RtStepResult {
  RtStep step = RtStep::kMemoryLock;
  bool requested = false;  ///< false: not asked for (--cpu not given, pm_qos off); neither ok nor refused
  bool ok = false;
  int error = 0;  ///< errno when refused
};

/// The set-up's result; owns the cpu_dma_latency request (released on destruction). Move-only.
class RtSetup {
 public:
  RtSetup() = default;
  RtSetup(RtSetup&& other) noexcept;
  RtSetup& operator=(RtSetup&& other) noexcept;
  RtSetup(const RtSetup&) = delete;
  RtSetup& operator=(const RtSetup&) = delete;
  ~RtSetup();

  /// True when every requested step succeeded.
  bool realtime() const;
  const std::array<RtStepResult, kRtStepCount>& steps() const { return steps_; }
  const RtStepResult& step(RtStep s) const { return steps_[static_cast<std::size_t>(s)]; }
  const RtRequest& request() const { return request_; }

  /// Refused steps for reports, "; "-separated, e.g. "CPU affinity (CPU 7): Invalid argument";
  /// empty when realtime().
  std::string Refused() const;
  /// One line per refused step: "<program>: WARNING: NOT REAL-TIME: <step> refused: <error> — <hint>\n".
  std::string Warnings(const char* program) const;

 private:
  friend RtSetup PrepareRealtimeThread(const RtRequest& request, const RtSyscalls& sys);

  std::array<RtStepResult, kRtStepCount> steps_{};
  RtRequest request_;
  int pm_qos_fd_ = -1;
  void (*close_pm_qos_)(int) = nullptr;
};

/// Runs the steps on the calling thread (memory lock: the whole process). Non-RT.
RtSetup PrepareRealtimeThread(const RtRequest& request, const RtSyscalls& sys = LinuxRtSyscalls());

/// Reads one byte per page of `bytes` (volatile), so every page is resident. Non-RT.
void PrefaultPages(std::span<const std::byte> bytes);

}  // namespace palpa::rt
