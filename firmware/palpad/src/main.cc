// palpad: the controller. Start-up (non-RT) verifies every input before the loop runs; the loop
// runs on this thread; the CSV and summary are written after it stops.

#include <atomic>
#include <csignal>
#include <cstdio>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/device_sim/sim_device.h"
#include "palpa/palpad/options.h"
#include "palpa/proxy/proxy.h"
#include "palpa/servo/realtime.h"
#include "palpa/servo/report.h"
#include "palpa/servo/servo_loop.h"
#include "palpa/trace/trace.h"

namespace {

using palpa::palpad::kExitBadInput;
using palpa::palpad::kExitNotBuilt;
using palpa::palpad::kExitOk;
using palpa::palpad::kExitRunFailed;

constexpr int kServoFifoPriority = 80;

std::atomic<bool> g_stop{false};

extern "C" void OnStopSignal(int) { g_stop.store(true, std::memory_order_release); }

void InstallStopHandlers() {
  struct sigaction sa {};
  sa.sa_handler = OnStopSignal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: the pacing sleep returns EINTR and the loop sees the flag
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

int Fail(int code, const std::string& message) {
  std::fprintf(stderr, "palpad: %s\n", message.c_str());
  return code;
}

int Run(const palpa::palpad::Options& o) {
  if (o.device == "falcon") return Fail(kExitNotBuilt, "the Falcon backend is not built yet (only --device sim)");

  // Field: read, then verify every byte before anything uses it. `blob` outlives the loop.
  auto blob = palpa::blob::ReadFile(o.field_path.c_str());
  if (!blob) return Fail(kExitBadInput, o.field_path + ": " + blob.error().what());
  const auto field = palpa::blob::Verify(*blob);
  if (!field) return Fail(kExitBadInput, o.field_path + ": " + field.error().what());

  auto samples = palpa::trace::ReadTrace(o.trace_path);
  if (!samples) return Fail(kExitBadInput, samples.error().message);

  palpa::proxy::ProxyConfig config;
  config.k_n_per_m = o.k_n_per_m;
  config.max_force_n = o.max_force_n;
  const auto params = palpa::proxy::MakeProxyParams(config, field->voxel_m);
  if (!params) return Fail(kExitBadInput, std::string("parameters: ") + params.error());

  // Open the output now so that an unwritable path fails before the run, not after it.
  auto out = palpa::servo::AtomicFile::Create(o.out_path);
  if (!out) return Fail(kExitBadInput, out.error());

  palpa::device_sim::SimDevice device(std::move(*samples), o.rate_hz);
  palpa::servo::ServoLoop loop(*field, *params, device, device.TickCount(), g_stop);

  InstallStopHandlers();
  if (!o.fast) {
    const palpa::servo::RealtimeReport rt = palpa::servo::PrepareRealtimeThread(kServoFifoPriority);
    if (!rt.ok()) std::fprintf(stderr, "palpad: warning: running paced but not RT:\n%s", rt.problems.c_str());
  }
  const palpa::servo::RunEnd end = loop.Run(o.fast, o.rate_hz);

  // After the run: non-RT again.
  int code = kExitOk;
  if (end == palpa::servo::RunEnd::kStopped) std::fprintf(stderr, "palpad: stopped by signal\n");
  if (end == palpa::servo::RunEnd::kDeviceError) {
    std::fprintf(stderr, "palpad: device error: zero force written, run stopped\n");
    code = kExitRunFailed;
  }
  if (!palpa::servo::WriteCsv(out->file(), loop.rows())) return Fail(kExitRunFailed, "cannot write " + o.out_path);
  if (auto committed = out->Commit(); !committed) return Fail(kExitRunFailed, committed.error());

  const palpa::servo::ServoSummary summary = palpa::servo::Summarize(loop, o.fast, o.rate_hz);
  std::fputs(palpa::servo::SummaryText(summary).c_str(), stdout);
  if (!o.summary_json_path.empty()) {
    auto json = palpa::servo::AtomicFile::Create(o.summary_json_path);
    if (!json) return Fail(kExitRunFailed, json.error());
    if (std::fputs(palpa::servo::SummaryJson(summary).c_str(), json->file()) < 0)
      return Fail(kExitRunFailed, "cannot write " + o.summary_json_path);
    if (auto committed = json->Commit(); !committed) return Fail(kExitRunFailed, committed.error());
  }
  return code;
}

}  // namespace

int main(int argc, char** argv) {
  const std::span<const char* const> args(argv + 1, static_cast<std::size_t>(argc > 0 ? argc - 1 : 0));
  const auto options = palpa::palpad::ParseArgs(args);
  if (!options) {
    std::fprintf(stderr, "palpad: %s\n%s", options.error().c_str(), palpa::palpad::Usage());
    return kExitBadInput;
  }
  if (options->help) {
    std::fputs(palpa::palpad::Usage(), stdout);
    return kExitOk;
  }
  return Run(*options);
}
