#include "signals.h"

#include <signal.h>
#include <unistd.h>

#include <cstring>
#include <exception>

#include "palpa/io/temp_registry.h"

namespace palpa::palpad {
namespace {

std::atomic<bool>* g_stop = nullptr;
std::atomic<int> g_stop_signal{0};
std::atomic<EmergencyHook> g_hook{nullptr};
std::atomic<void*> g_hook_ctx{nullptr};
std::atomic<int> g_fatal_entered{0};
static_assert(std::atomic<EmergencyHook>::is_always_lock_free && std::atomic<int>::is_always_lock_free);

constexpr int kStopSignals[] = {SIGHUP,  SIGINT,  SIGQUIT, SIGTERM, SIGUSR1,   SIGUSR2, SIGALRM, SIGVTALRM, SIGPROF,
                                SIGXCPU, SIGXFSZ, SIGIO,   SIGPWR,  SIGSTKFLT, SIGTSTP, SIGTTIN, SIGTTOU};
constexpr int kFatalSignals[] = {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS};

void Say(const char* text) {
  const std::size_t n = std::strlen(text);  // strlen is async-signal-safe (POSIX.1-2008 TC2)
  (void)!write(STDERR_FILENO, text, n);
}

extern "C" void OnStopSignal(int sig) {
  int none = 0;
  g_stop_signal.compare_exchange_strong(none, sig, std::memory_order_acq_rel);
  if (g_stop != nullptr) g_stop->store(true, std::memory_order_release);
}

// Everything here is async-signal-safe except the hook's device transfer for the real Falcon
// (libusb may lock or allocate); alarm(2) bounds it: a hang there ends in SIGALRM's default
// action instead of a process that holds its last force.
void Emergency(int sig) {
  if (g_fatal_entered.exchange(1, std::memory_order_acq_rel) != 0) return;  // a second crash: just die
  const int removed = io::UnlinkRegisteredTempPaths();
  Say("palpad: fatal signal ");
  Say(SignalName(sig));
  Say(removed > 0 ? ": temporary files removed; " : ": ");
  if (g_stop != nullptr) g_stop->store(true, std::memory_order_release);  // the loop starts no new tick
  if (EmergencyHook hook = g_hook.load(std::memory_order_acquire); hook != nullptr) {
    Say("commanding zero force\n");
    (void)signal(SIGALRM, SIG_DFL);
    (void)alarm(2);
    hook(g_hook_ctx.load(std::memory_order_acquire));
    (void)alarm(0);
  } else {
    Say("no device force to zero\n");
  }
}

extern "C" void OnFatalSignal(int sig) {
  Emergency(sig);
  (void)signal(sig, SIG_DFL);
  (void)raise(sig);  // pending until this handler returns (sig is blocked here), then fatal
}

[[noreturn]] void OnTerminate() {
  Emergency(SIGABRT);
  (void)signal(SIGABRT, SIG_DFL);
  std::abort();
}

}  // namespace

const char* SignalName(int sig) {
  switch (sig) {
    case SIGHUP:
      return "SIGHUP";
    case SIGINT:
      return "SIGINT";
    case SIGQUIT:
      return "SIGQUIT";
    case SIGILL:
      return "SIGILL";
    case SIGTRAP:
      return "SIGTRAP";
    case SIGABRT:
      return "SIGABRT";
    case SIGBUS:
      return "SIGBUS";
    case SIGFPE:
      return "SIGFPE";
    case SIGUSR1:
      return "SIGUSR1";
    case SIGSEGV:
      return "SIGSEGV";
    case SIGUSR2:
      return "SIGUSR2";
    case SIGPIPE:
      return "SIGPIPE";
    case SIGALRM:
      return "SIGALRM";
    case SIGTERM:
      return "SIGTERM";
    case SIGSTKFLT:
      return "SIGSTKFLT";
    case SIGTSTP:
      return "SIGTSTP";
    case SIGTTIN:
      return "SIGTTIN";
    case SIGTTOU:
      return "SIGTTOU";
    case SIGXCPU:
      return "SIGXCPU";
    case SIGXFSZ:
      return "SIGXFSZ";
    case SIGVTALRM:
      return "SIGVTALRM";
    case SIGPROF:
      return "SIGPROF";
    case SIGIO:
      return "SIGIO";
    case SIGPWR:
      return "SIGPWR";
    case SIGSYS:
      return "SIGSYS";
    default:
      break;
  }
  if (sig >= SIGRTMIN && sig <= SIGRTMAX) return "a real-time signal (SIGRTMIN..SIGRTMAX)";
  return "an unnamed signal";
}

void InstallSignalHandlers(std::atomic<bool>* stop) {
  g_stop = stop;
  struct sigaction sa {};
  sa.sa_handler = OnStopSignal;
  sigfillset(&sa.sa_mask);  // one handler at a time
  // SA_RESTART: a stop during start-up must not turn a file read into an I/O error. The pacing
  // sleep (clock_nanosleep) and poll are never restarted (signal(7)), so the loop still wakes.
  sa.sa_flags = SA_RESTART;
  for (const int sig : kStopSignals) sigaction(sig, &sa, nullptr);
  for (int sig = SIGRTMIN; sig <= SIGRTMAX; ++sig) sigaction(sig, &sa, nullptr);

  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  sigemptyset(&ignore.sa_mask);
  sigaction(SIGPIPE, &ignore, nullptr);

  struct sigaction fatal {};
  fatal.sa_handler = OnFatalSignal;
  sigfillset(&fatal.sa_mask);
  fatal.sa_flags = 0;
  for (const int sig : kFatalSignals) sigaction(sig, &fatal, nullptr);
  std::set_terminate(&OnTerminate);
}

int StopSignal() { return g_stop_signal.load(std::memory_order_acquire); }

void SetEmergencyHook(EmergencyHook hook, void* ctx) {
  g_hook_ctx.store(ctx, std::memory_order_release);
  g_hook.store(hook, std::memory_order_release);
}

}  // namespace palpa::palpad
