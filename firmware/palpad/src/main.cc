// palpad: the controller. Start-up (non-RT) verifies every input and opens every line and device
// before the loop runs; then the real-time set-up, and the loop runs on this thread while a
// drain thread streams its telemetry to --out and --status, and a watchdog thread watches it.

#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "button_input.h"
#include "falcon_session.h"
#include "palpa/blob/blob.h"
#include "palpa/device_sim/sim_device.h"
#include "palpa/gpio_linux/gpiod_lines.h"
#include "palpa/io/atomic_file.h"
#include "palpa/io/file_safety.h"
#include "palpa/net/client.h"
#include "palpa/net_server/listener.h"
#include "palpa/palpad/options.h"
#include "palpa/proxy/proxy.h"
#include "palpa/rt/realtime.h"
#include "palpa/servo/report.h"
#include "palpa/servo/servo_loop.h"
#include "palpa/servo/telemetry_drain.h"
#include "palpa/servo/watchdog.h"
#include "palpa/trace/trace.h"
#include "recorder.h"
#include "scripted_swap.h"
#include "signals.h"

namespace {

using palpa::palpad::kExitBadInput;
using palpa::palpad::kExitNoDevice;
using palpa::palpad::kExitOk;
using palpa::palpad::kExitRunFailed;

// Telemetry ring: 16384 samples (~2 MB) = 16 s at 1 kHz, 1.6 s at 10 kHz of backlog before a
// sample is dropped; the drain empties it every millisecond.
constexpr std::size_t kTelemetryCapacity = 16384;

// Set by every stop signal (signals.h), from the first line of main: a signal during start-up
// ends the run before any force.
std::atomic<bool> g_stop{false};

// Clears the fatal-signal hook before the device it points at goes away.
struct EmergencyHookGuard {
  EmergencyHookGuard() = default;
  EmergencyHookGuard(const EmergencyHookGuard&) = delete;
  EmergencyHookGuard& operator=(const EmergencyHookGuard&) = delete;
  ~EmergencyHookGuard() { palpa::palpad::SetEmergencyHook(nullptr, nullptr); }
};

int Fail(int code, const std::string& message) {
  std::fprintf(stderr, "palpad: %s\n", message.c_str());
  return code;
}

// Watchdog trip, on the watchdog thread: one loud line (the loop latches the fault itself).
void OnWatchdogTrip(void*, std::int64_t stalled_ns) {
  std::fprintf(stderr,
               "palpad: WATCHDOG: a servo tick has not completed for %.1f ms (device layer stalled): fault "
               "latched; the device's own timeout and the stopped tick line zero the force\n",
               static_cast<double>(stalled_ns) / 1e6);
}

// Every output palpad replaces must be a regular file (or new) and none of its inputs (issue 18):
// checked before anything is read or moved. "--out /dev/null" writes no CSV at all, so it passes.
int CheckOutputs(const palpa::palpad::Options& o) {
  const std::vector<std::string> inputs = {o.field_path, o.trace_path,    o.config_path,
                                           o.key_file,   o.swap_at_field, o.firmware_path};
  const std::pair<const char*, const std::string*> outputs[] = {
      {"--out", &o.out_path},       {"--summary-json", &o.summary_json_path},
      {"--status", &o.status_path}, {"--latency-histogram", &o.latency_histogram_path},
      {"--record", &o.record_path}, {"--record-timing", &o.record_timing_path}};
  for (const auto& [option, path] : outputs) {
    if (path->empty() || (path == &o.out_path && *path == "/dev/null")) continue;
    if (auto ok = palpa::io::CheckOutputTarget(*path, inputs); !ok)
      return Fail(ok.error().fault == palpa::io::Fault::kBadInput ? kExitBadInput : kExitRunFailed,
                  std::string(option) + " " + ok.error().message);
  }
  return kExitOk;
}

int Run(const palpa::palpad::Options& o) {
  if (const int refused = CheckOutputs(o); refused != kExitOk) return refused;
  palpa::proxy::ProxyConfig config;
  config.k_n_per_m = o.k_n_per_m;
  config.max_force_n = o.max_force_n;

  // --listen (docs/upload.md): the listener owns the field's buffer and a spare of --max-blob
  // each, allocated now; the start-up field is read into the first.
  std::unique_ptr<palpa::net_server::UploadListener> listener;
  palpa::servo::TelemetryDrain* live_drain = nullptr;  // set once the drain exists
  std::atomic<bool> loop_running{false};
  palpa::servo::ServoLoop* live_loop = nullptr;
  std::optional<palpa::blob::VerifiedField> owned;  // without --listen: the field file; outlives the loop
  std::optional<palpa::blob::FieldView> field_view;
  if (!o.listen.empty()) {
    auto key = palpa::net::ReadKeyFile(o.key_file);
    if (!key) return Fail(kExitBadInput, "--key-file " + key.error().message);
    palpa::net_server::ListenerConfig lc;
    lc.host = o.listen_host;
    lc.port = static_cast<std::uint16_t>(o.listen_port);
    lc.key = *key;
    lc.max_blob = static_cast<std::uint64_t>(o.max_blob);
    lc.read_timeout_ms = static_cast<std::int64_t>(o.net_timeout_ms);
    lc.proxy = config;
    lc.avoid_cpu = static_cast<int>(o.cpu);
    lc.log = [](const std::string& line) { std::fprintf(stderr, "palpad: %s\n", line.c_str()); };
    lc.fill_status = [&](palpa::net::ControllerStatus& st) {
      st.rate_hz = o.rate_hz;
      st.running = loop_running.load(std::memory_order_acquire);
      if (live_loop != nullptr) st.dropped = live_loop->telemetry().dropped();
      if (live_drain == nullptr) return;
      const palpa::servo::DrainStatus d = live_drain->LiveStatus();
      st.ticks = d.samples + st.dropped;
      st.overruns = d.overruns;
      st.max_tick_ns = d.max_compute_ns;
      st.force_clamps = d.force_clamps;
      st.estops = d.estop_events;
      st.contact_ticks = d.contact_ticks;
      st.last_tick = d.last_tick;
      st.t_s = d.t_s;
      st.hip_m = d.hip_m;
      st.proxy_m = d.proxy_m;
      st.force_n = d.force_n;
      st.contact = d.contact;
      st.swap_ramp = d.swap_ramp;
    };
    auto created = palpa::net_server::UploadListener::Create(std::move(lc));
    if (!created) return Fail(kExitBadInput, created.error());
    listener = std::move(*created);
    auto loaded = listener->LoadInitial(o.field_path);
    if (!loaded) return Fail(kExitBadInput, loaded.error());
    field_view.emplace(*loaded);
    std::fprintf(stderr, "palpad: listening on %s:%u (uploads up to %.0f bytes)\n", o.listen_host.c_str(),
                 static_cast<unsigned>(listener->port()), o.max_blob);
  } else {
    // Field: read as stored (a v2 blob is sampled in place), then verify every byte before
    // anything uses it. `owned` outlives the loop.
    auto field = palpa::blob::LoadFile(o.field_path.c_str());
    if (!field) return Fail(kExitBadInput, o.field_path + ": " + field.error().what());
    owned.emplace(std::move(*field));
    field_view.emplace(owned->view());
  }

  std::vector<palpa::trace::TraceSample> samples;  // the real Falcon is moved by hand: no trace
  if (o.device != "falcon") {
    auto read = palpa::trace::ReadTrace(o.trace_path);
    if (!read) return Fail(kExitBadInput, read.error().message);
    samples = std::move(*read);
  }

  const auto params = palpa::proxy::MakeProxyParams(config, field_view->voxel_m);
  if (!params) return Fail(kExitBadInput, std::string("parameters: ") + params.error());

  // --swap-at N:FIELD: the second field, read and verified now like the first.
  std::optional<palpa::blob::VerifiedField> swap_blob;
  std::optional<palpa::servo::ServoField> swap_field;
  if (!o.swap_at_field.empty()) {
    auto verified = palpa::blob::LoadFile(o.swap_at_field.c_str());
    if (!verified) return Fail(kExitBadInput, "--swap-at " + o.swap_at_field + ": " + verified.error().what());
    swap_blob.emplace(std::move(*verified));
    const palpa::blob::FieldView& view = swap_blob->view();
    const auto swap_params = palpa::proxy::MakeProxyParams(config, view.voxel_m);
    if (!swap_params) return Fail(kExitBadInput, std::string("--swap-at parameters: ") + swap_params.error());
    swap_field.emplace(view, *swap_params, view.blob_size);
  }

  // Open the output now so that an unwritable path fails before the run, not after it.
  // /dev/null (a service running for hours): no CSV at all.
  const bool keep_csv = o.out_path != "/dev/null";
  std::optional<palpa::io::AtomicFile> out;
  if (keep_csv) {
    auto file = palpa::io::AtomicFile::Create(o.out_path);
    if (!file) return Fail(kExitBadInput, file.error());
    out.emplace(std::move(*file));
  }

  // GPIO lines before the device: a missing chip is reported before anything moves.
  std::unique_ptr<palpa::gpio_linux::GpiodInput> estop;
  std::unique_ptr<palpa::gpio_linux::GpiodOutput> tick_line;
  if (o.estop_line) {
    auto line = palpa::gpio_linux::GpiodInput::Open("--estop", *o.estop_line, "palpad-estop");
    if (!line) return Fail(kExitNoDevice, line.error());
    estop = std::move(*line);
  }
  if (o.tick_line) {
    auto line = palpa::gpio_linux::GpiodOutput::Open("--tick-gpio", *o.tick_line, "palpad-tick", false);
    if (!line) return Fail(kExitNoDevice, line.error());
    tick_line = std::move(*line);
  }

  std::optional<palpa::device_sim::SimDevice> sim;
  std::unique_ptr<palpa::palpad::FalconSession> falcon;
  palpa::device::HapticDevice* device = nullptr;
  if (o.device == "sim") {
    sim.emplace(std::move(samples), o.rate_hz);
    device = &*sim;
  } else {
    // virtual-falcon replays as many ticks as a sim replay of the same trace would.
    const std::size_t ticks =
        o.device == "virtual-falcon" ? palpa::device_sim::SimDevice(samples, o.rate_hz).TickCount() : 0;
    auto session = palpa::palpad::FalconSession::Open(o, std::move(samples), ticks);
    if (!session) return Fail(session.error().exit_code, session.error().message);
    falcon = std::move(*session);
    device = &falcon->device();
  }
  // From here a crash commands zero torque first (best effort); cleared before `falcon` dies.
  EmergencyHookGuard emergency_hook;
  if (falcon) palpa::palpad::SetEmergencyHook(&palpa::palpad::FalconSession::EmergencyZero, falcon.get());

  palpa::servo::ServoConfig sc;
  sc.telemetry_capacity = kTelemetryCapacity;
  sc.wait_when_full = o.fast;  // lockstep replay: complete, deterministic output; paced: drop, never wait
  sc.overrun_fault_limit = static_cast<std::uint32_t>(o.overrun_limit);
  std::optional<palpa::palpad::DeviceButtonInput> estop_button;
  if (o.estop_button >= 0) estop_button.emplace(*device, o.estop_button);
  sc.estop = estop ? static_cast<palpa::gpio::DigitalInput*>(estop.get()) : estop_button ? &*estop_button : nullptr;
  sc.estop_active_high = o.estop_active_high;
  sc.estop_release_ticks = static_cast<std::uint32_t>(o.estop_debounce);
  sc.ramp_ticks = static_cast<std::uint32_t>(std::llround(o.ramp_ms * 1e-3 * o.rate_hz));
  sc.tick_line = tick_line.get();
  sc.swap_ramp_ticks = static_cast<std::uint32_t>(std::llround(o.swap_ramp_ms * 1e-3 * o.rate_hz));
  std::optional<palpa::palpad::ScriptedSwapDevice> scripted_swap;
  if (swap_field) {
    scripted_swap.emplace(*device, *swap_field, o.swap_at_tick);
    device = &*scripted_swap;
  }
  palpa::servo::ServoLoop loop(*field_view, *params, *device, sc, g_stop);
  if (scripted_swap) scripted_swap->Attach(loop);
  live_loop = &loop;
  if (listener) listener->Attach(loop);

  if (falcon) {
    if (auto homed = falcon->Home(g_stop, o.home_timeout_s); !homed) {
      (void)falcon->Finish();
      return Fail(homed.error().exit_code, homed.error().message);
    }
  }

  // Real-time set-up (paced runs): every refused step is one loud warning and marks the run.
  palpa::rt::RtSetup rt;
  if (!o.fast) {
    // Everything the loop reads or writes: its ring and histograms, and the field it samples.
    const auto loop_buffers = loop.buffers();
    std::vector<std::span<const std::byte>> buffers(loop_buffers.begin(), loop_buffers.end());
    if (listener) {
      for (const auto b : listener->buffers()) buffers.emplace_back(b);
    } else {
      buffers.emplace_back(owned->bytes());
    }
    if (swap_blob) buffers.emplace_back(swap_blob->bytes());
    palpa::rt::RtRequest request;
    request.cpu = static_cast<int>(o.cpu);
    request.priority = static_cast<int>(o.priority);
    request.buffers = buffers;
    rt = palpa::rt::PrepareRealtimeThread(request);
    std::fputs(rt.Warnings("palpad").c_str(), stderr);
  }

  // --record / --record-timing: a sink on the drain thread (the loop only fills the ring).
  std::unique_ptr<palpa::palpad::Recorder> recorder;
  if (!o.record_path.empty() || !o.record_timing_path.empty()) {
    auto opened = palpa::palpad::Recorder::Open(
        o.record_path, o.record_timing_path,
        "palpad --record: the HIP as read, device " + o.device + ", field " + o.field_path + ", " +
            (o.fast ? std::string("fast") : "paced at " + std::to_string(o.rate_hz) + " Hz"));
    if (!opened) return Fail(kExitBadInput, opened.error());
    recorder = std::move(*opened);
  }

  palpa::servo::DrainConfig dc;
  dc.sink = recorder.get();
  dc.csv = out ? out->file() : nullptr;
  dc.status_path = o.status_path;
  dc.rate_hz = o.rate_hz;
  dc.fast = o.fast;
  dc.realtime_requested = !o.fast;
  dc.realtime = !o.fast && rt.realtime();
  dc.rt_refused = rt.Refused();
  dc.avoid_cpu = static_cast<int>(o.cpu);
  palpa::servo::TelemetryDrain drain(loop.telemetry(), dc);
  if (!drain.WriteStatus("starting")) return Fail(kExitBadInput, "cannot write the status file " + o.status_path);
  if (const int err = drain.Start(); err != 0)
    return Fail(kExitRunFailed, std::string("cannot start the telemetry thread: ") + std::strerror(err));
  palpa::servo::Watchdog watchdog(
      loop, {static_cast<std::int64_t>(o.watchdog_ms * 1e6), &OnWatchdogTrip, nullptr, static_cast<int>(o.cpu)});
  if (!o.fast && o.watchdog_ms > 0) {
    if (const int err = watchdog.Start(); err != 0)
      return Fail(kExitRunFailed, std::string("cannot start the watchdog thread: ") + std::strerror(err));
  }

  live_drain = &drain;
  if (listener) {
    if (const int err = listener->Start(); err != 0)
      return Fail(kExitRunFailed, std::string("cannot start the listener thread: ") + std::strerror(err));
  }
  loop_running.store(true, std::memory_order_release);
  const palpa::servo::RunEnd end = loop.Run(o.fast, o.rate_hz);
  loop_running.store(false, std::memory_order_release);

  // After the run: non-RT again. The device first: zero torque and its report before any output
  // is committed, so that an output error below cannot skip them.
  const int device_code = falcon ? falcon->Finish() : kExitOk;
  if (listener) listener->Stop();
  watchdog.Stop();
  drain.Stop(palpa::servo::RunEndName(end));
  if (recorder) {
    if (auto committed = recorder->Commit(loop.counters().dropped_rows); !committed)
      return Fail(kExitRunFailed, "--record: " + committed.error());
    std::fputs(recorder->Report().c_str(), stderr);
  }
  int code = kExitOk;
  switch (end) {
    case palpa::servo::RunEnd::kStopped:
      std::fprintf(stderr, "palpad: stopped by signal %s: zero force written\n",
                   palpa::palpad::SignalName(palpa::palpad::StopSignal()));
      break;
    case palpa::servo::RunEnd::kDeviceError:
      std::fprintf(stderr, "palpad: device error: zero force written, run stopped\n");
      code = kExitRunFailed;
      break;
    case palpa::servo::RunEnd::kOverrunFault:
      std::fprintf(stderr, "palpad: FAULT: %u consecutive overruns at %g Hz: zero force written, run stopped\n",
                   sc.overrun_fault_limit, o.rate_hz);
      code = kExitRunFailed;
      break;
    case palpa::servo::RunEnd::kWatchdogFault:
      std::fprintf(stderr, "palpad: FAULT: watchdog: a tick did not complete within %g ms: zero force written\n",
                   o.watchdog_ms);
      code = kExitRunFailed;
      break;
    case palpa::servo::RunEnd::kEnded:
    case palpa::servo::RunEnd::kInvalidRate:
      break;
  }
  if (device_code != kExitOk) code = kExitRunFailed;
  if (sim) {
    const auto& f = sim->last_force_n();
    std::fprintf(stderr, "palpad: sim device: last force written (%g, %g, %g) N\n", f[0], f[1], f[2]);
  }
  if (loop.counters().dropped_rows != 0)
    std::fprintf(stderr, "palpad: warning: %llu telemetry samples dropped (ring full): %s misses them\n",
                 static_cast<unsigned long long>(loop.counters().dropped_rows), o.out_path.c_str());
  if (drain.csv_failed()) return Fail(kExitRunFailed, "cannot write " + o.out_path);
  if (out) {
    if (auto committed = out->Commit(); !committed) return Fail(kExitRunFailed, committed.error());
  }

  palpa::servo::ServoSummary summary = palpa::servo::Summarize(loop, o.fast, o.rate_hz);
  summary.end = palpa::servo::RunEndName(end);
  summary.watchdog_trips = watchdog.trips();
  summary.realtime_requested = !o.fast;
  summary.realtime = !o.fast && rt.realtime();
  summary.rt_refused = rt.Refused();
  std::fputs(palpa::servo::SummaryText(summary).c_str(), stdout);
  if (!o.summary_json_path.empty()) {
    auto json = palpa::io::AtomicFile::Create(o.summary_json_path);
    if (!json) return Fail(kExitRunFailed, json.error());
    if (std::fputs(palpa::servo::SummaryJson(summary).c_str(), json->file()) < 0)
      return Fail(kExitRunFailed, "cannot write " + o.summary_json_path);
    if (auto committed = json->Commit(); !committed) return Fail(kExitRunFailed, committed.error());
  }
  if (!o.latency_histogram_path.empty()) {
    auto hist = palpa::io::AtomicFile::Create(o.latency_histogram_path);
    if (!hist) return Fail(kExitRunFailed, hist.error());
    if (std::fputs(palpa::servo::LatencyHistogramText(loop.wake_latency(), summary).c_str(), hist->file()) < 0)
      return Fail(kExitRunFailed, "cannot write " + o.latency_histogram_path);
    if (auto committed = hist->Commit(); !committed) return Fail(kExitRunFailed, committed.error());
  }
  return code;
}

}  // namespace

int main(int argc, char** argv) {
  palpa::palpad::InstallSignalHandlers(&g_stop);
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
  if (options->check_config) {
    std::fputs(palpa::palpad::OptionsToml(*options).c_str(), stdout);
    return kExitOk;
  }
  return Run(*options);
}
