#include "palpa/rt/realtime.h"

#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <utility>

namespace palpa::rt {
namespace {

constexpr std::size_t kPageBytes = 4096;  // the smallest page of every target; larger pages only touch more often

int LinuxLockMemory() { return mlockall(MCL_CURRENT | MCL_FUTURE) == 0 ? 0 : errno; }

int LinuxSetAffinity(int cpu) {
  if (cpu < 0 || cpu >= CPU_SETSIZE) return EINVAL;
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(static_cast<std::size_t>(cpu), &set);
  return pthread_setaffinity_np(pthread_self(), sizeof set, &set);
}

int LinuxSetFifo(int priority) {
  sched_param param{};
  param.sched_priority = priority;
  return pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
}

int LinuxOpenPmQos(std::int32_t max_us) {
  // The request holds while the file stays open (Documentation/power/pm_qos_interface.rst).
  const int fd = open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
  if (fd < 0) return -errno;
  if (write(fd, &max_us, sizeof max_us) != static_cast<ssize_t>(sizeof max_us)) {
    const int err = errno != 0 ? errno : EIO;
    close(fd);
    return -err;
  }
  return fd;
}

void LinuxClosePmQos(int fd) { close(fd); }

int LinuxSetThreadName(const char* name) { return pthread_setname_np(pthread_self(), name); }

constexpr RtSyscalls kLinux = {LinuxLockMemory, LinuxSetAffinity, LinuxSetFifo,
                               LinuxOpenPmQos,  LinuxClosePmQos,  LinuxSetThreadName};

// Grows the stack by kPrefaultStackBytes below the caller and writes each page, so that the loop's
// deepest call does not page-fault (MCL_FUTURE keeps the pages locked once present).
[[gnu::noinline]] void PrefaultStack() {
  volatile unsigned char stack[kPrefaultStackBytes];
  for (std::size_t i = 0; i < kPrefaultStackBytes; i += kPageBytes) stack[i] = 0;
  [[maybe_unused]] const unsigned char last = stack[kPrefaultStackBytes - 1];  // a volatile read: "used"
}

const char* Hint(RtStep step, int error) {
  switch (step) {
    case RtStep::kMemoryLock:
      return "page faults may stall the loop; needs CAP_IPC_LOCK or LimitMEMLOCK=infinity (palpad.service)";
    case RtStep::kPrefault:
      return "";
    case RtStep::kAffinity:
      return error == EINVAL ? "no such CPU, or not in this process's allowed set (see nproc, taskset -p)"
                             : "the thread may migrate between CPUs";
    case RtStep::kFifo:
      return "the loop runs SCHED_OTHER and any process can delay it; needs CAP_SYS_NICE or "
             "LimitRTPRIO (palpad.service), and RT budget in the cgroup";
    case RtStep::kPmQos:
      return "deep C-state exits add wake-up latency; needs write access to /dev/cpu_dma_latency";
    case RtStep::kThreadName:
      return "tools (top, perf) will not show palpad-servo";
  }
  return "";
}

}  // namespace

const RtSyscalls& LinuxRtSyscalls() { return kLinux; }

const char* RtStepName(RtStep step) {
  switch (step) {
    case RtStep::kMemoryLock:
      return "memory lock";
    case RtStep::kPrefault:
      return "pre-fault";
    case RtStep::kAffinity:
      return "CPU affinity";
    case RtStep::kFifo:
      return "SCHED_FIFO";
    case RtStep::kPmQos:
      return "cpu_dma_latency";
    case RtStep::kThreadName:
      return "thread name";
  }
  return "?";
}

void PrefaultPages(std::span<const std::byte> bytes) {
  const volatile std::byte* p = bytes.data();
  for (std::size_t i = 0; i < bytes.size(); i += kPageBytes) (void)p[i];
  if (!bytes.empty()) (void)p[bytes.size() - 1];
}

RtSetup::RtSetup(RtSetup&& other) noexcept
    : steps_(other.steps_),
      request_(other.request_),
      pm_qos_fd_(std::exchange(other.pm_qos_fd_, -1)),
      close_pm_qos_(other.close_pm_qos_) {}

RtSetup& RtSetup::operator=(RtSetup&& other) noexcept {
  if (this != &other) {
    if (pm_qos_fd_ >= 0 && close_pm_qos_ != nullptr) close_pm_qos_(pm_qos_fd_);
    steps_ = other.steps_;
    request_ = other.request_;
    pm_qos_fd_ = std::exchange(other.pm_qos_fd_, -1);
    close_pm_qos_ = other.close_pm_qos_;
  }
  return *this;
}

RtSetup::~RtSetup() {
  if (pm_qos_fd_ >= 0 && close_pm_qos_ != nullptr) close_pm_qos_(pm_qos_fd_);
}

bool RtSetup::realtime() const {
  for (const RtStepResult& s : steps_)
    if (s.requested && !s.ok) return false;
  return true;
}

namespace {

std::string Describe(const RtStepResult& s, const RtRequest& r) {
  std::string out = RtStepName(s.step);
  char detail[48] = "";
  if (s.step == RtStep::kAffinity) std::snprintf(detail, sizeof detail, " (CPU %d)", r.cpu);
  if (s.step == RtStep::kFifo) std::snprintf(detail, sizeof detail, " (priority %d)", r.priority);
  out += detail;
  return out;
}

}  // namespace

std::string RtSetup::Refused() const {
  std::string out;
  for (const RtStepResult& s : steps_) {
    if (!s.requested || s.ok) continue;
    if (!out.empty()) out += "; ";
    out += Describe(s, request_) + ": " + std::strerror(s.error);
  }
  return out;
}

std::string RtSetup::Warnings(const char* program) const {
  std::string out;
  for (const RtStepResult& s : steps_) {
    if (!s.requested || s.ok) continue;
    out += std::string(program) + ": WARNING: NOT REAL-TIME: " + Describe(s, request_) +
           " refused: " + std::strerror(s.error) + " — " + Hint(s.step, s.error) + "\n";
  }
  return out;
}

RtSetup PrepareRealtimeThread(const RtRequest& request, const RtSyscalls& sys) {
  RtSetup setup;
  setup.request_ = request;
  setup.request_.buffers = {};  // the caller's span need not outlive the set-up
  const auto record = [&](RtStep step, bool requested, int error) {
    RtStepResult& r = setup.steps_[static_cast<std::size_t>(step)];
    r.step = step;
    r.requested = requested;
    r.ok = requested && error == 0;
    r.error = requested ? error : 0;
  };

  record(RtStep::kMemoryLock, true, sys.lock_memory());
  PrefaultStack();
  for (const std::span<const std::byte> b : request.buffers) PrefaultPages(b);
  record(RtStep::kPrefault, true, 0);
  record(RtStep::kAffinity, request.cpu >= 0, request.cpu >= 0 ? sys.set_affinity(request.cpu) : 0);
  record(RtStep::kFifo, true,
         request.priority >= 1 && request.priority <= 99 ? sys.set_fifo(request.priority) : EINVAL);
  if (request.pm_qos) {
    const int fd = sys.open_pm_qos(0);
    record(RtStep::kPmQos, true, fd >= 0 ? 0 : -fd);
    if (fd >= 0) {
      setup.pm_qos_fd_ = fd;
      setup.close_pm_qos_ = sys.close_pm_qos;
    }
  } else {
    record(RtStep::kPmQos, false, 0);
  }
  record(RtStep::kThreadName, request.thread_name != nullptr,
         request.thread_name != nullptr ? sys.set_thread_name(request.thread_name) : 0);
  return setup;
}

}  // namespace palpa::rt
