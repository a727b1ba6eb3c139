// palpad's signal policy (issue 18, docs/runtime.md "Every way out writes zero force first"):
//  - stop signals (SIGHUP, SIGINT, SIGQUIT, SIGTERM, SIGUSR1, SIGUSR2, SIGALRM, SIGVTALRM, SIGPROF,
//    SIGXCPU, SIGXFSZ, SIGIO, SIGPWR, SIGSTKFLT, SIGTSTP, SIGTTIN, SIGTTOU, SIGRTMIN..SIGRTMAX)
//    set the stop flag: the loop ends with a zero-force write, the device is shut down, the
//    outputs are committed and palpad exits normally. SIGTSTP & co. stop the run rather than
//    suspend a process that holds a force on a hand;
//  - SIGPIPE is ignored (a closed pipe is an ordinary write error);
//  - fatal signals (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS) and std::terminate
//    unlink the registered temporary files, call the emergency hook (zero torque, best effort)
//    and then die of the same signal (core dump as usual).
// SIGKILL and SIGSTOP cannot be caught: docs/runtime.md says what the device then does.
#pragma once

#include <atomic>

namespace palpa::palpad {

/// Installs the handlers above; `stop` must live for the rest of the process. Non-RT, once.
void InstallSignalHandlers(std::atomic<bool>* stop);

/// The first stop signal received, 0 if none.
int StopSignal();

/// Name of a signal ("SIGHUP", "SIGRTMIN+3"), for messages. Async-signal-safe for the fixed names.
const char* SignalName(int sig);

/// Emergency hook for fatal signals: `hook(ctx)` tries to command zero force, writing at most one
/// line on fd 2 with write(2). It runs in a signal handler on whichever thread crashed, bounded by
/// alarm(2 s). nullptr: none. Set it once the device is open; clear it before the device dies.
using EmergencyHook = void (*)(void* ctx);
void SetEmergencyHook(EmergencyHook hook, void* ctx);

}  // namespace palpa::palpad
