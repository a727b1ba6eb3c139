#include "falcon_session.h"

#include <time.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <utility>

#include "palpa/device_falcon/firmware_loader.h"
#include "palpa/device_falcon/libusb_transport.h"

namespace palpa::palpad {

using device_falcon::ConfigureResult;
using device_falcon::FalconDevice;
using device_falcon::HomeResult;

std::expected<std::unique_ptr<FalconSession>, SessionFailure> FalconSession::Open(const Options& o,
                                                                                  std::vector<trace::TraceSample> trace,
                                                                                  std::size_t tick_limit) {
  // Inputs first: a bad firmware file or fault list is bad input whatever the device does.
  std::optional<device_falcon::FirmwareImage> firmware;
  if (!o.firmware_path.empty()) {
    auto fw = device_falcon::ReadFirmwareFile(o.firmware_path);
    if (!fw) return std::unexpected(SessionFailure{kExitBadInput, fw.error()});
    firmware = std::move(*fw);
  }
  std::unique_ptr<FalconSession> s(new FalconSession);
  if (o.device == "virtual-falcon") {
    auto faults = device_virtual_falcon::ParseFaults(o.faults);
    if (!faults) return std::unexpected(SessionFailure{kExitBadInput, faults.error()});
    device_virtual_falcon::VirtualFalconConfig vc;
    vc.rate_hz = o.rate_hz;
    vc.firmware_loaded = !firmware.has_value();  // given a file, the virtual Falcon needs it
    vc.trace = std::move(trace);
    vc.faults = std::move(*faults);
    auto v = std::make_unique<device_virtual_falcon::VirtualFalcon>(std::move(vc));
    s->virtual_ = v.get();
    s->transport_ = std::move(v);
  } else {
    auto t = device_falcon::LibusbTransport::Open(static_cast<int>(o.usb_index));
    if (!t) return std::unexpected(SessionFailure{kExitNoDevice, t.error().message});
    s->transport_ = std::move(*t);
  }
  device_falcon::FalconConfig config;
  config.tick_limit = tick_limit;
  s->device_ = std::make_unique<FalconDevice>(*s->transport_, config);

  std::string log;
  const ConfigureResult r = s->device_->Configure(firmware ? &*firmware : nullptr, device_falcon::LoaderConfig{}, log);
  std::fputs(log.c_str(), stderr);
  switch (r) {
    case ConfigureResult::kOk:
      return s;
    case ConfigureResult::kNoFirmware:
      return std::unexpected(SessionFailure{kExitNoDevice, "Falcon has no firmware running and no --firmware given"});
    case ConfigureResult::kLoadFailed:
      return std::unexpected(SessionFailure{kExitRunFailed, "Falcon firmware upload failed (see above)"});
    case ConfigureResult::kDisconnected:
      return std::unexpected(SessionFailure{kExitNoDevice, "Falcon disconnected during set-up"});
    case ConfigureResult::kUsbError:
      break;
  }
  return std::unexpected(SessionFailure{kExitRunFailed, "Falcon USB set-up failed (see above)"});
}

std::expected<void, SessionFailure> FalconSession::Home(const std::atomic<bool>& stop, double timeout_s) {
  std::fputs("palpad: Falcon homing (LED red): pull the grip all the way out, then push it straight in\n", stderr);
  switch (device_->Home(stop, timeout_s)) {
    case HomeResult::kHomed:
      break;
    case HomeResult::kStopped:
      return std::unexpected(SessionFailure{kExitOk, "stopped by signal during homing; zero torque sent"});
    case HomeResult::kTimeout:
    case HomeResult::kFrozen:
    case HomeResult::kFault:
      return std::unexpected(SessionFailure{kExitRunFailed, device_->FaultMessage()});
  }
  std::fputs("palpad: Falcon homed (LED blue); forces on (LED green)\n", stderr);
  if (!device_->Activate()) return std::unexpected(SessionFailure{kExitRunFailed, "Falcon could not be activated"});
  return {};
}

int FalconSession::Finish() {
  device_->Shutdown();
  int code = kExitOk;
  if (device_->fault().code != device_falcon::FalconFault::kNone) {
    std::fprintf(stderr, "palpad: %s\n", device_->FaultMessage().c_str());
    code = kExitRunFailed;
  }
  const device_falcon::FalconCounters& c = device_->counters();
  std::fprintf(stderr,
               "palpad: falcon: %llu packet exchanges, max reply %.3f ms, %llu bytes skipped re-framing, "
               "%llu split replies, %llu saturated commands, max %d Newton iterations\n",
               static_cast<unsigned long long>(c.exchanges), static_cast<double>(c.max_reply_ns) / 1e6,
               static_cast<unsigned long long>(c.discarded_bytes), static_cast<unsigned long long>(c.split_replies),
               static_cast<unsigned long long>(c.saturated_commands), c.max_fk_iterations);
  if (virtual_ != nullptr) {
    std::fprintf(stderr, "palpad: virtual falcon: torque %s at the end, %llu commands with torque before homing\n",
                 virtual_->torque_is_zero() ? "zero" : "NOT zero",
                 static_cast<unsigned long long>(virtual_->torque_before_homed()));
  }
  return code;
}

void FalconSession::EmergencyZero(void* self) {
  auto* s = static_cast<FalconSession*>(self);
  auto say = [](const char* text) { (void)!write(STDERR_FILENO, text, std::strlen(text)); };
  // Twice, 5 ms apart: a servo tick in flight on another thread (it sees the stop flag only at
  // its next start) may send one more force after the first zero.
  (void)s->device_->EmergencyZero();
  const timespec pause = {0, 5'000'000};
  (void)nanosleep(&pause, nullptr);
  say(s->device_->EmergencyZero() ? "palpad: zero-torque packet sent to the Falcon\n"
                                  : "palpad: the zero-torque packet could not be sent: the Falcon keeps its last "
                                    "command (docs/falcon.md)\n");
  if (s->virtual_ != nullptr)
    say(s->virtual_->torque_is_zero() ? "palpad: virtual falcon: torque zero after the fatal signal\n"
                                      : "palpad: virtual falcon: torque NOT zero after the fatal signal\n");
}

FalconSession::~FalconSession() {
  if (device_) device_->Shutdown();
}

}  // namespace palpa::palpad
